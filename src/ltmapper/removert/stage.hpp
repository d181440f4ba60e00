// ltmapper removert: the LT-removert stage from files (batch, on a run, lifelong add).
#pragma once

#include "ltmapper/io/files.hpp"
#include "ltmapper/removert/hd.hpp"
#include "ltmapper/removert/ld.hpp"

#include <string>
#include <utility>
#include <vector>

namespace ltm::removert {

struct StageReport {
  std::vector<std::string> sessions;
  std::vector<HdStats> hd;
  std::vector<std::pair<int, int>> pairs;
  std::vector<LdStats> ld;
  std::vector<std::vector<int>> new_keyframes;  // per pair: query keyframe indices reported new
  double seconds = 0;
  std::size_t peak_rss_bytes = 0;
};
// The whole stage from files: session directories (io::LoadSession), one world pose file per
// session (KITTI, keyframe order: LT-SLAM's aligned/<session>/poses_world.txt or sim truth), and
// the output directory (layout in docs/FORMATS.md, "LT-removert output"). Session 0 is central.
StageReport RunRemovertStage(const RemovertConfig& cfg, const std::vector<std::string>& session_dirs,
                             const std::vector<std::string>& poses_files, const std::string& out_dir,
                             int threads = 0);
// `cfg` with the rotation uncertainty of each session's poses that LT-SLAM measured, for the
// sessions `names` in the stage's order (any of the run's aligned sessions, in any order): the
// manifest's io::ManifestSession::rotation_sigma_deg, against the run's central (0 for it). LD's
// tolerances follow them (RemovertConfig::ForPair, LdRotationSigmaDeg); a session the manifest
// does not measure leaves its pairs at pose_sigma_deg.
RemovertConfig WithAlignment(const RemovertConfig& cfg, const io::RunManifest& manifest,
                             const std::vector<std::string>& names);
// The aligned sessions of a run manifest, in run order: their input folders, their
// aligned_dir/<session>/poses_world.txt and their names.
struct RunSessions {
  std::vector<std::string> dirs, poses, names;
};
RunSessions SessionsOfRun(const io::RunManifest& manifest, const std::string& aligned_dir);
// The stage on an LT-SLAM output: the aligned sessions of `aligned_dir`'s run manifest
// (io::ReadRunManifest), in run order, with their aligned/<session>/poses_world.txt and the
// manifest's rotation uncertainty (WithAlignment). Pair folder
// positions are therefore positions among the manifest's aligned sessions, as LT-map reads them.
StageReport RunRemovertStageOnRun(const RemovertConfig& cfg, const std::string& aligned_dir,
                                  const std::string& out_dir, int threads = 0);
// Lifelong add: the stage for one more session, into an existing output `changes_dir`.
// `session_dirs` / `poses_files` are the run's aligned sessions in run order with the new one
// last (position q). Runs HD removal of the new session only and LD of its pair (central 0 or,
// with `pairs: consecutive`, q-1), whose HD-free and HD maps are read from changes_dir, never
// recomputed; the sensor comes from the central's scans as in the batch. Replaces
// changes_dir/<new>/ (with its own report.json) and changes_dir/pair_<c>_<q>/ whole. With the
// same poses the files equal those of the batch stage. Cost: one session's HD + one pair's LD.
StageReport AddToRemovertStage(const RemovertConfig& cfg, const std::vector<std::string>& session_dirs,
                               const std::vector<std::string>& poses_files, const std::string& changes_dir,
                               int threads = 0);

}  // namespace ltm::removert
