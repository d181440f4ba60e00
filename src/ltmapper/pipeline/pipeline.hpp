// ltmapper pipeline: `ltmapper run` chains LT-SLAM -> LT-removert -> LT-map through the files of
// docs/FORMATS.md (the paper's file-based protocol), so every stage's output can be inspected,
// and a run that stops half-way resumes at the first stage without a finished output.
// `WriteReport` gathers a demo directory's evaluation JSON/Markdown and PNG renders into
// report.md and report.html.
#pragma once

#include "ltmapper/core/core.hpp"

#include <string>
#include <vector>

namespace ltm::pipeline {

struct RunConfig {
  std::string slam_config;      // LT-SLAM params file ("" = built-in defaults)
  std::string removert_config;  // LT-removert params file ("" = built-in defaults)
  std::string map_config;       // LT-map params file ("" = built-in defaults)
  std::string store_name = "map.ltmap";                          // store file inside the out dir
  std::string from_stage = "auto";  // auto: resume after the last finished stage whose inputs and
                                    // resolved config are unchanged; else rerun from it
  bool export_maps = true;          // write live.pcd, meta.pcd and objects/ next to the store

  template <class V>
  void Visit(V& v) {
    v("slam_config", slam_config);
    v("removert_config", removert_config);
    v("map_config", map_config);
    v("store_name", store_name);
    v("from_stage", from_stage, {"auto", "slam", "removert", "map"});
    v("export_maps", export_maps);
  }
};

struct StageTiming {
  std::string stage;
  bool skipped = false;  // finished output found (resume)
  double seconds = 0.0;
};

struct RunReport {
  std::vector<std::string> sessions;      // names, central first
  std::vector<std::string> aligned;       // sessions LT-SLAM aligned (central included)
  std::vector<std::string> not_aligned;   // with the reason
  std::vector<StageTiming> stages;
  std::size_t map_points_live = 0, map_points_meta = 0, objects = 0;
  std::uint64_t store_bytes = 0;
  double seconds = 0.0;
  std::size_t peak_rss_bytes = 0;
};

// Runs the three stages on `session_dirs` (first = central) into `out_dir`:
//   out_dir/aligned/  out_dir/changes/  out_dir/<store_name>  [live.pcd meta.pcd objects/]
//   out_dir/run_report.json, run_report.md
// A query session LT-SLAM cannot align is reported and left out of the later stages. The later
// stages take the sessions, their order and which aligned from aligned/manifest.yaml; a stage
// that runs replaces its whole folder (io::StagingDir), so a rerun into a used out_dir gives the
// files of a fresh one.
// With `world_poses` (one KITTI world-pose file per session, in session order) the first stage
// places the sessions by those poses instead of aligning them (slam::WriteGivenPoses): LT-removert
// and LT-map on poses from elsewhere, e.g. the simulator's truth or a GNSS / INS solution.
RunReport RunPipeline(const RunConfig& cfg, const std::vector<std::string>& session_dirs,
                      const std::string& out_dir, int threads = 0,
                      const std::vector<std::string>& world_poses = {});
std::string FormatRunReport(const RunReport& report);

// ------------------------------------------------------------------------------ lifelong add
struct AddReport {
  std::string session;            // the new session's name
  bool already_in_map = false;    // it was integrated before: nothing was done
  std::string aligned_to;         // the map session its loops tie it to
  int loops_accepted = 0, registrations = 0;
  double seconds_slam = 0, seconds_removert = 0, seconds_map = 0, seconds = 0;
  std::uint64_t store_bytes_before = 0, store_bytes = 0;
  std::size_t map_points_live = 0, objects = 0;
  std::size_t peak_rss_bytes = 0;
};
// Integrates one more drive into the map a `run` built in `out_dir` (`ltmapper add`):
//  1. LT-SLAM aligns it to the world frame with the map's sessions held fixed: against the
//     central session, else the other aligned sessions newest first (loops, anchor, graph as in
//     the batch); not aligned to any is an error and nothing changes;
//  2. LT-removert runs HD removal of this session only and LD of its pair (removert::
//     AddToRemovertStage: the earlier session's maps are read, not recomputed);
//  3. the run manifest gets the session (last), the store integrates it in one transaction and
//     live.pcd / meta.pcd / objects/ are exported again; the stage markers then hold the keys
//     of `run` with the grown session list, so such a run finds nothing to do.
// The work follows the new session's and its reference's sizes, not the number of sessions.
// A session already in the store is a no-op; one that an earlier add left in the manifest but
// not in the store (stopped half-way) is added again from the start.
// With `world_poses` (a KITTI file of the session's world poses, as `run --poses`) step 1 places
// the session by them instead of aligning it, and measures their rotation error against the
// map's sessions in the same order (slam::MeasureGivenPoses; LD's prior where no loop verifies).
AddReport AddSession(const RunConfig& cfg, const std::string& out_dir, const std::string& session_dir,
                     int threads = 0, const std::string& world_poses = "");
std::string FormatAddReport(const AddReport& report);

// Resume markers: a finished stage writes `marker` holding its key (the session directories, the
// stage's resolved config and the keys of the stages before it); a later run skips the stage
// only when the marker holds the same key, so a changed parameter or session list reruns it.
void MarkStageDone(const std::string& marker, const std::string& key);
bool StageDone(const std::string& marker, const std::string& key);

// A report is a list of items in order: Markdown files (their text is included) and PNG
// pictures (linked, with a caption). Writes `out_base`.md and a self-contained-looking
// `out_base`.html (tables and lists converted, pictures referenced relative to the report).
struct ReportItem {
  std::string path;     // .md or .png
  std::string caption;  // for pictures; defaults to the file name
};
void WriteReport(const std::string& out_base, const std::string& title,
                 const std::vector<ReportItem>& items);
// Markdown (CommonMark with GitHub's tables, by cmark-gfm) as HTML, every heading one level down;
// raw HTML in it is not passed through.
std::string MarkdownToHtml(const std::string& markdown);

}  // namespace ltm::pipeline
