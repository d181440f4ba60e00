// A run's output layout: stage folders published whole (StagingDir), the file names of the
// stages' outputs (layout::), and the run manifest LT-SLAM writes (docs/FORMATS.md).
#include "ltmapper/io/files.hpp"

#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;

namespace ltm::io {
namespace {

constexpr const char* kTmpInfix = ".tmp-";
constexpr const char* kOldInfix = ".old-";
constexpr const char* kManifestName = "manifest.yaml";
constexpr int kManifestVersion = 1;

std::string Join(const std::string& a, const std::string& b) { return (fs::path(a) / b).string(); }

// The pid of "<base><infix><pid>-<n>", or 0 when `name` is not such a name.
long OwnerPid(const std::string& name, const std::string& prefix) {
  if (name.compare(0, prefix.size(), prefix) != 0) return 0;
  const std::string rest = name.substr(prefix.size());
  const std::size_t dash = rest.find('-');
  if (dash == 0 || dash == std::string::npos || dash > 9) return 0;
  if (rest.find_first_not_of("0123456789") != dash) return 0;
  return std::stol(rest.substr(0, dash));
}

// Removes "<dir>.tmp-<pid>-<n>" and "<dir>.old-<pid>-<n>" folders whose process is gone.
void RemoveDeadTemps(const fs::path& dir) {
  const fs::path parent = dir.has_parent_path() ? dir.parent_path() : fs::path(".");
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(parent, ec)) {
    const std::string name = e.path().filename().string();
    for (const char* infix : {kTmpInfix, kOldInfix}) {
      const long pid = OwnerPid(name, dir.filename().string() + infix);
      if (pid <= 0 || ::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;
      spdlog::info("removing {} (left by process {}, which no longer runs)", e.path().string(), pid);
      fs::remove_all(e.path(), ec);
    }
  }
}

void CheckReplaceable(const fs::path& dir, const std::string& identity_file) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) return;
  if (!fs::is_directory(dir, ec)) throw Error(dir.string() + ": exists and is not a directory");
  if (fs::is_empty(dir, ec) || fs::exists(dir / identity_file, ec)) return;
  throw Error(dir.string() + ": not empty and not an ltmapper stage output (no " + identity_file +
              "); refusing to replace it: remove it or choose another output folder");
}

std::string UniqueSibling(const fs::path& dir, const char* infix) {
  static std::atomic<unsigned long> counter{0};
  return dir.string() + infix + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

}  // namespace

// ---------------------------------------------------------------------------- StagingDir
StagingDir::StagingDir(std::string final_dir, std::string identity_file) {
  fs::path dir(final_dir);
  if (dir.filename().empty()) dir = dir.parent_path();  // "out/aligned/"
  final_ = dir.string();
  CheckReplaceable(dir, identity_file);
  if (dir.has_parent_path()) MakeDirs(dir.parent_path().string());
  RemoveDeadTemps(dir);
  tmp_ = UniqueSibling(dir, kTmpInfix);
  MakeWritableDir(tmp_);
}

StagingDir::~StagingDir() {
  if (published_) return;
  std::error_code ec;
  fs::remove_all(tmp_, ec);
}

void StagingDir::Publish() {
  std::error_code ec;
  std::string old;
  if (fs::exists(final_, ec)) {
    old = UniqueSibling(fs::path(final_), kOldInfix);
    fs::rename(final_, old, ec);
    if (ec) throw Error(final_ + ": cannot move the previous output aside: " + ec.message());
  }
  fs::rename(tmp_, final_, ec);
  if (ec) {
    if (!old.empty()) fs::rename(old, final_);  // put the previous output back
    throw Error(final_ + ": cannot rename the new output " + tmp_ + " into place: " + ec.message());
  }
  published_ = true;
  if (!old.empty()) fs::remove_all(old, ec);
}

// ------------------------------------------------------------------------------- layout
namespace layout {
std::string AlignedDir(const std::string& out_dir) { return Join(out_dir, "aligned"); }
std::string ChangesDir(const std::string& out_dir) { return Join(out_dir, "changes"); }
std::string ObjectsDir(const std::string& out_dir) { return Join(out_dir, "objects"); }
std::string ManifestFile(const std::string& aligned_dir) { return Join(aligned_dir, kManifestName); }
std::string PosesWorldFile(const std::string& aligned_dir, const std::string& session) {
  return Join(Join(aligned_dir, session), "poses_world.txt");
}
std::string AnchorFile(const std::string& aligned_dir, const std::string& session) {
  return Join(Join(aligned_dir, session), "anchor.txt");
}
std::string SessionChangesDir(const std::string& changes_dir, const std::string& session) {
  return Join(changes_dir, session);
}
std::string StaticMapFile(const std::string& changes_dir, const std::string& session) {
  return StaticMapIn(SessionChangesDir(changes_dir, session));
}
std::string StaticMapIn(const std::string& session_changes_dir) { return Join(session_changes_dir, "static_map.pcd"); }
std::string HdMapIn(const std::string& session_changes_dir) { return Join(session_changes_dir, "hd_map.pcd"); }
std::string PairDirName(int central, int query) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "pair_%02d_%02d", central, query);
  return buf;
}
std::string KeyframeDirName(int index) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06d", index);
  return buf;
}
std::string ExactRayTruthDir(const std::string& pair_truth_dir) { return Join(pair_truth_dir, "exact_ray"); }
}  // namespace layout

// ----------------------------------------------------------------------------- manifest
std::vector<ManifestSession> RunManifest::Aligned() const {
  std::vector<ManifestSession> out;
  for (const auto& s : sessions)
    if (s.aligned) out.push_back(s);
  return out;
}

void WriteRunManifest(const std::string& aligned_dir, const RunManifest& m) {
  YAML::Emitter y;
  y << YAML::BeginMap << YAML::Key << "version" << YAML::Value << kManifestVersion;
  y << YAML::Key << "sessions" << YAML::Value << YAML::BeginSeq;
  for (const auto& s : m.sessions) {
    y << YAML::BeginMap << YAML::Key << "name" << YAML::Value << YAML::DoubleQuoted << s.name
      << YAML::Key << "dir" << YAML::Value << YAML::DoubleQuoted << s.dir << YAML::Key << "aligned"
      << YAML::Value << s.aligned << YAML::Key << "reason" << YAML::Value << YAML::DoubleQuoted << s.reason;
    if (s.rotation_sigma_deg > 0.0) y << YAML::Key << "rotation_sigma_deg" << YAML::Value << s.rotation_sigma_deg;
    y << YAML::EndMap;
  }
  y << YAML::EndSeq << YAML::Key << "slam_config" << YAML::Value << YAML::Literal << m.slam_config;
  y << YAML::EndMap;
  WriteFileAtomic(layout::ManifestFile(aligned_dir), [&](std::ostream& os) {
    os << "# ltmapper run manifest, written by LT-SLAM (docs/FORMATS.md): sessions in run order,\n"
          "# central first. LT-removert, LT-map and the pipeline read it.\n"
       << y.c_str() << "\n";
  });
}

bool HasRunManifest(const std::string& aligned_dir) {
  return fs::is_regular_file(layout::ManifestFile(aligned_dir));
}

RunManifest ReadRunManifest(const std::string& aligned_dir) {
  const std::string path = layout::ManifestFile(aligned_dir);
  if (!fs::is_regular_file(path)) throw Error(path + ": run manifest not found (LT-SLAM output)");
  RunManifest m;
  try {
    const YAML::Node root = YAML::LoadFile(path);
    if (!root["version"] || root["version"].as<int>() != kManifestVersion)
      throw Error(path + ": manifest version is not " + std::to_string(kManifestVersion));
    for (const auto& n : root["sessions"]) {
      ManifestSession s{n["name"].as<std::string>(), n["dir"].as<std::string>(), n["aligned"].as<bool>(),
                        n["reason"] ? n["reason"].as<std::string>() : std::string()};
      if (s.name.empty()) throw Error(path + ": a session with an empty name");
      if (n["rotation_sigma_deg"]) s.rotation_sigma_deg = n["rotation_sigma_deg"].as<double>();
      if (!(s.rotation_sigma_deg >= 0.0)) throw Error(path + ": session " + s.name + ": rotation_sigma_deg must be >= 0");
      m.sessions.push_back(std::move(s));
    }
    if (root["slam_config"]) m.slam_config = root["slam_config"].as<std::string>();
  } catch (const YAML::Exception& e) {
    throw Error(path + ": malformed run manifest: " + e.what());
  }
  if (m.sessions.empty()) throw Error(path + ": the run manifest lists no session");
  return m;
}

}  // namespace ltm::io
