// ltmapper io: atomic writes, stage folders, the run layout (file names of the stage folders),
// the run manifest and indexed scan files.
#pragma once

#include "ltmapper/core/core.hpp"

#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

namespace ltm::io {

// Writes through a temporary file "<path>.tmp-<pid>-<n>" and renames it over `path` when
// `write` returns. On exception the temporary is removed and the exception is rethrown.
void WriteFileAtomic(const std::string& path, const std::function<void(std::ostream&)>& write);
// Same, for writers that need a path (e.g. PCL): `write(tmp_path)` must create tmp_path.
void WritePathAtomic(const std::string& path, const std::function<void(const std::string&)>& write);
// A file's whole content; ltm::Error naming it when it cannot be opened.
std::string ReadFileText(const std::string& path);
// Creates a directory and its parents; throws on failure.
void MakeDirs(const std::string& dir);
// MakeDirs, then checks that files can be created in `dir` ("<dir>: output directory is not
// writable: <reason>"): the stages call it on their output before any work, so a read-only OUT
// fails in the first second, not after the stage ran.
void MakeWritableDir(const std::string& dir);

// ------------------------------------------------------------------------- stage folders
// A stage output folder is built whole in a fresh temporary folder "<dir>.tmp-<pid>-<n>" next to
// `dir`, and Publish() puts it in place of `dir` (the old folder is renamed aside, then removed),
// so no file of an earlier run (a session or pair folder of a longer session list, a keyframe of
// other parameters) can survive into this run's output. Destroyed unpublished, the temporary is
// removed. An existing `dir` is replaced only when it is empty or holds `identity_file` (a file
// the stage always writes, e.g. "report.json"): anything else is an error naming `dir`, so a
// mistyped --out never deletes a user's folder. Temporaries left by processes that no longer
// run are removed.
class StagingDir {
 public:
  StagingDir(std::string final_dir, std::string identity_file);
  ~StagingDir();
  StagingDir(const StagingDir&) = delete;
  StagingDir& operator=(const StagingDir&) = delete;
  const std::string& path() const { return tmp_; }  // write here
  void Publish();
 private:
  std::string final_, tmp_;
  bool published_ = false;
};

// ------------------------------------------------------------------ run layout and manifest
// One owner for the file names of a run's output (docs/FORMATS.md): the stages, eval and the
// pipeline build every path with these.
namespace layout {
std::string AlignedDir(const std::string& out_dir);   // OUT/aligned   (LT-SLAM)
std::string ChangesDir(const std::string& out_dir);   // OUT/changes   (LT-removert)
std::string ObjectsDir(const std::string& out_dir);   // OUT/objects   (LT-map export)
std::string ManifestFile(const std::string& aligned_dir);                            // manifest.yaml
std::string PosesWorldFile(const std::string& aligned_dir, const std::string& session);
std::string AnchorFile(const std::string& aligned_dir, const std::string& session);
std::string SessionChangesDir(const std::string& changes_dir, const std::string& session);
std::string StaticMapFile(const std::string& changes_dir, const std::string& session);  // HD-free map
// The files of one LT-removert session folder (changes/<session>/, or its staging copy).
std::string StaticMapIn(const std::string& session_changes_dir);  // static_map.pcd (HD-free)
std::string HdMapIn(const std::string& session_changes_dir);      // hd_map.pcd (removed points)
// Pair folder of LT-removert: "pair_<c>_<q>", c and q = positions (2 digits) of the sessions
// among the manifest's aligned sessions, in manifest order.
std::string PairDirName(int central, int query);
std::string KeyframeDirName(int index);  // "000123"
// The simulator's second change truth of a pair (truth/pair_<c>_<q>/exact_ray: strong / weak by a
// ray cast straight at each point, beside the beam truth of the scans' own rays).
std::string ExactRayTruthDir(const std::string& pair_truth_dir);
}  // namespace layout

// What LT-SLAM knows and every later stage needs, written once as aligned/manifest.yaml: the
// sessions in the run's order (central first), their names (= output folder names), input
// folders, whether they are aligned (and why not), and the resolved LT-SLAM params. LT-removert,
// LT-map and the pipeline read the session order and the aligned set from it instead of listing
// directories.
struct ManifestSession {
  std::string name;    // output folder name: aligned/<name>, changes/<name>
  std::string dir;     // input session folder (absolute)
  bool aligned = false;
  std::string reason;  // why not aligned ("" when aligned)
  // [deg] the rotation uncertainty of its poses against the earlier sessions' that LT-SLAM measured
  // (slam::SessionAlignment::rotation_sigma_deg); 0 = not measured (the central, poses given)
  double rotation_sigma_deg = 0.0;
};
struct RunManifest {
  std::vector<ManifestSession> sessions;  // run order, central first
  std::string slam_config;                // resolved LT-SLAM params (YAML text)
  std::vector<ManifestSession> Aligned() const;  // aligned sessions, in run order
};
void WriteRunManifest(const std::string& aligned_dir, const RunManifest& manifest);
// Throws ltm::Error naming the file when it is missing or malformed.
RunManifest ReadRunManifest(const std::string& aligned_dir);
bool HasRunManifest(const std::string& aligned_dir);

// Numeric index of a scan file name ("000123.pcd" -> 123); throws when not a number.
int FileIndex(const std::string& filename);
// Regular files in `dir` with the extension `ext` (".pcd"), sorted by FileIndex.
std::vector<std::string> ListIndexedFiles(const std::string& dir, const std::string& ext);

}  // namespace ltm::io
