// The LT-removert stage from files: sessions + world poses -> changes/ (docs/FORMATS.md).
//
// Keyframe assignment (what LT-map consumes). Every output point belongs to exactly one keyframe:
//  - central static, HD and ND points: the nearest central keyframe (3D distance to its position);
//    so the per-keyframe static clouds partition the central static map (no duplicates) and each
//    ND point lies in the static cloud of the keyframe it is assigned to;
//  - PD points: the nearest keyframe among the central keyframes and the "new" query keyframes
//    (query keyframes farther than out.new_keyframe_dist_m from every central keyframe). A PD
//    point whose nearest candidate is a central keyframe farther than out.assign_radius_m goes to
//    its nearest query keyframe, which becomes new too. New keyframes are written under
//    pair_*/new_keyframes/ in their own local frame, listed in keyframes.csv and report.json;
//    LT-map creates map keyframes for them.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iomanip>
#include <limits>
#include <set>
#include <sstream>

namespace ltm::removert {
namespace {

namespace fs = std::filesystem;
using detail::KeyframePart, detail::WriteKeyframeDir;

std::string Index6(int index) { return io::layout::KeyframeDirName(index); }

// Member indices per bucket.
std::vector<std::vector<std::uint32_t>> Buckets(const std::vector<std::uint32_t>& owner, std::size_t n) {
  std::vector<std::vector<std::uint32_t>> b(n);
  for (std::size_t i = 0; i < owner.size(); ++i)
    if (owner[i] < n) b[owner[i]].push_back(std::uint32_t(i));
  return b;
}

// ---- the stage's steps -------------------------------------------------------------------

// One session as the stage holds it: its keyframes and, once HD removal ran, its maps.
struct SessionData {
  std::string name;
  std::vector<WorldKeyframe> kfs;
  PointCloud static_map, hd_map;
};

// Independent output files written at once (each to a temporary name, then renamed): a stage's
// maps are tens of MB, and one core writing them while the others wait was LT-removert's largest
// serial step after the kd-tree builds (issue 18).
void WriteAtOnce(const std::vector<std::function<void()>>& writes, int threads) {
  ParallelFor(writes.size(), threads, [&](std::size_t i) { writes[i](); });
}

// HD removal of session `s`; writes `dir` (static_map.pcd, hd_map.pcd, map.ply).
HdStats RemoveSessionHd(SessionData& sd, int s, const std::string& dir, const RemovertConfig& cfg, int threads) {
  spdlog::info("removert: HD removal of {} ({} keyframes{})", sd.name, sd.kfs.size(), cfg.tiles_stage ? ", tile by tile" : "");
  HdResult hd;
  try {
    hd = cfg.tiles_stage ? RemoveHdTiled(sd.kfs, cfg, threads) : RemoveHd(sd.kfs, cfg, threads);
  } catch (const Error& e) {  // name the session: an empty scan rejects it, as LT-SLAM does
    throw Error("removert: session '" + sd.name + "': " + e.what());
  }
  const HdStats& st = hd.stats;
  spdlog::info("removert: {}: map {} points, candidates {}, reverted {}, removed {} + {} dilated ({:.2f} %), "
               "{:.1f} s map + {:.1f} s votes",
               sd.name, st.map_points, st.candidates, st.reverted, st.removed, st.dilated,
               st.map_points ? 100.0 * double(st.removed + st.dilated) / double(st.map_points) : 0.0,
               st.seconds_map, st.seconds_votes);
  io::MakeDirs(dir);
  const auto ses = std::uint16_t(s);
  std::vector<std::function<void()>> writes{[&] { io::WritePcd(io::layout::StaticMapIn(dir), hd.static_map); },
                                            [&] { io::WritePcd(io::layout::HdMapIn(dir), hd.hd_map); }};
  if (cfg.write_ply)
    writes.emplace_back([&] {
      io::WritePly(dir + "/map.ply", {{&hd.static_map, PointClass::kStatic, ses}, {&hd.hd_map, PointClass::kHD, ses}});
    });
  WriteAtOnce(writes, threads);
  sd.static_map = std::move(hd.static_map);
  sd.hd_map = std::move(hd.hd_map);
  return st;
}

// The LD clouds of a pair and its labelled changes.ply, written at once.
void WriteLdClouds(const std::string& dir, const LdResult& ld, const PointCloud& cmap, int c, int q,
                   const RemovertConfig& cfg, int threads) {
  io::MakeDirs(dir);
  std::vector<std::function<void()>> writes;
  for (const auto& [name, cloud] : {std::pair{"pd_strong", &ld.pd_strong}, {"pd_weak", &ld.pd_weak},
                                    {"nd_strong", &ld.nd_strong}, {"nd_weak", &ld.nd_weak},
                                    {"pd_unobserved", &ld.pd_unobserved}, {"nd_residue", &ld.nd_residue},
                                    {"pd_residue", &ld.pd_residue}})
    writes.emplace_back([&dir, name = std::string(name), cloud = cloud] { io::WritePcd(dir + "/" + name + ".pcd", *cloud); });
  std::vector<bool> unchanged(cmap.size());  // central static minus ND
  for (std::size_t i = 0; i < cmap.size(); ++i) unchanged[i] = !ld.central_nd[i];
  const auto cs = std::uint16_t(c), qs = std::uint16_t(q);
  constexpr std::int32_t kNoObject = -1, kNewTerritory = 1;  // object field of changes.ply
  if (cfg.write_ply)
    writes.emplace_back([&] {
      io::WritePly(dir + "/changes.ply", {{&cmap, PointClass::kStatic, cs, kNoObject, &unchanged},
                                          {&ld.nd_strong, PointClass::kNDStrong, cs},
                                          {&ld.nd_weak, PointClass::kNDWeak, cs},
                                          {&ld.pd_strong, PointClass::kPDStrong, qs},
                                          {&ld.pd_weak, PointClass::kPDWeak, qs},
                                          {&ld.pd_unobserved, PointClass::kPDStrong, qs, kNewTerritory},
                                          {&ld.nd_residue, PointClass::kHD, cs},
                                          {&ld.pd_residue, PointClass::kHD, qs}});
    });
  WriteAtOnce(writes, threads);
}

// Which keyframe every output point of a pair belongs to (rule at the top of this file).
// Buckets: [0, nc) central keyframes, nc + j query keyframe j.
struct KeyframeAssignment {
  std::size_t nc = 0;
  std::array<PointCloud, detail::kKeyframeClouds> clouds;  // what the keyframes' clouds are cut from
  std::array<std::vector<std::vector<std::uint32_t>>, detail::kKeyframeClouds> members;  // [cloud][bucket]
  std::vector<int> new_list;  // query keyframe positions that become new map keyframes
};

KeyframeAssignment AssignKeyframes(const SessionData& c, const SessionData& q, const LdResult& ld,
                                   const RemovertConfig& cfg, int threads) {
  using namespace detail;
  KeyframeAssignment a;
  a.nc = c.kfs.size();
  a.clouds[kKfStatic] = c.static_map;
  a.clouds[kKfHd] = c.hd_map;
  for (int k = 0; k < kKeyframeClouds; ++k)
    for (auto m : KeyframeCloudLd(k)) a.clouds[std::size_t(k)].append(ld.*m);
  const KeyframeOwners owners(c.kfs, q.kfs, cfg, threads);
  const std::size_t nk = a.nc + q.kfs.size();
  std::vector<bool> owns_pd(nk, false);
  for (int k = 0; k < kKeyframeClouds; ++k) {
    const bool pd = k == kKfPdStrong || k == kKfPdWeak;
    a.members[std::size_t(k)] = Buckets(pd ? owners.Pd(a.clouds[std::size_t(k)]) : owners.Central(a.clouds[std::size_t(k)]), nk);
    if (pd)
      for (std::size_t b = 0; b < nk; ++b) owns_pd[b] = owns_pd[b] || !a.members[std::size_t(k)][b].empty();
  }
  a.new_list = owners.NewKeyframes(owns_pd);
  return a;
}

// keyframes/NNNNNN/ for every central keyframe and new_keyframes/NNNNNN/ for the new ones.
void WriteKeyframeFolders(const std::string& dir, const SessionData& c, const SessionData& q, int ci, int qi,
                          const KeyframeAssignment& a, const RemovertConfig& cfg, int threads) {
  using namespace detail;
  auto pick = [&](int cloud, std::size_t bucket) {
    return a.clouds[std::size_t(cloud)].select(a.members[std::size_t(cloud)][bucket]);
  };
  ParallelFor(a.nc, threads, [&](std::size_t k) {
    std::array<PointCloud, kKeyframeClouds> clouds;
    for (int cl = 0; cl < kKeyframeClouds; ++cl) clouds[std::size_t(cl)] = pick(cl, k);
    WriteKeyframeDir(dir + "/keyframes/" + Index6(c.kfs[k].index), c.kfs[k].T_world_sensor,
                     CentralKeyframeParts(std::move(clouds), ci, qi), cfg);
  });
  ParallelFor(a.new_list.size(), threads, [&](std::size_t t) {
    const std::size_t j = std::size_t(a.new_list[t]);
    WriteKeyframeDir(dir + "/new_keyframes/" + Index6(q.kfs[j].index), q.kfs[j].T_world_sensor,
                     NewKeyframeParts(pick(kKfPdStrong, a.nc + j), pick(kKfPdWeak, a.nc + j), qi), cfg);
  });
}

// Points per keyframe bucket and cloud (keyframes.csv).
std::vector<std::array<std::size_t, detail::kKeyframeClouds>> Counts(const KeyframeAssignment& a) {
  std::vector<std::array<std::size_t, detail::kKeyframeClouds>> n(a.members[0].size());
  for (std::size_t b = 0; b < n.size(); ++b)
    for (std::size_t c = 0; c < a.members.size(); ++c) n[b][c] = a.members[c][b].size();
  return n;
}

// LD of the pair (c, q) written to `dir`; returns its stats and the new keyframes' indices.
std::pair<LdStats, std::vector<int>> DetectPair(const SessionData& c, const SessionData& q, int ci, int qi,
                                                const std::string& dir, const RemovertConfig& cfg, int threads) {
  spdlog::info("removert: LD {} vs {}", c.name, q.name);
  const RemovertConfig pair_cfg = cfg.ForPair(std::size_t(ci), std::size_t(qi));
  const LdResult ld = cfg.tiles_stage ? DetectLdTiled(c.static_map, q.static_map, c.kfs, q.kfs, pair_cfg, threads)
                                      : DetectLd(c.static_map, q.static_map, c.kfs, q.kfs, pair_cfg, threads);
  spdlog::info("removert: {}: ND strong {} weak {} (unobserved {}), PD strong {} weak {} (unobserved {}); residues of "
               "movers (HD) {} of {}, {} of {} ({:.1f} s)",
               io::layout::PairDirName(ci, qi), ld.stats.nd_strong, ld.stats.nd_weak, ld.stats.nd_unobserved,
               ld.stats.pd_strong, ld.stats.pd_weak, ld.stats.pd_unobserved, ld.stats.nd_residue, c.name,
               ld.stats.pd_residue, q.name, ld.stats.seconds);
  WriteLdClouds(dir, ld, c.static_map, ci, qi, cfg, threads);
  const KeyframeAssignment a = AssignKeyframes(c, q, ld, cfg, threads);
  if (cfg.write_keyframes) WriteKeyframeFolders(dir, c, q, ci, qi, a, cfg, threads);
  detail::WriteKeyframesCsv(dir, c.kfs, q.kfs, ci, qi, Counts(a), a.new_list);
  std::vector<int> new_idx;
  for (int j : a.new_list) new_idx.push_back(q.kfs[std::size_t(j)].index);
  return {ld.stats, new_idx};
}

// Pairs: (central 0, q) for every query, or consecutive (q-1, q).
int PairCentral(const RemovertConfig& cfg, int q) { return cfg.pairs == "consecutive" ? q - 1 : 0; }

void WriteHdJson(io::json::Writer& w, const std::string& name, std::size_t keyframes, const HdStats& h) {
  w.BeginObject().String("name", name).Int("keyframes", keyframes).Int("map_points", h.map_points);
  w.Int("candidates", h.candidates).Int("reverted", h.reverted).Int("removed", h.removed);
  w.Int("dilated", h.dilated).BeginArray("removed_per_resolution");
  for (const auto n : h.removed_per_resolution) w.Int(n);
  w.EndArray().Number("seconds_map", h.seconds_map).Number("seconds_votes", h.seconds_votes).EndObject();
}

void WritePairJson(io::json::Writer& w, int c, int q, const LdStats& l, const std::vector<int>& new_keyframes) {
  w.BeginObject().Int("central", c).Int("query", q).String("dir", io::layout::PairDirName(c, q));
  w.Int("nd_strong", l.nd_strong).Int("nd_weak", l.nd_weak);
  w.Int("pd_strong", l.pd_strong).Int("pd_weak", l.pd_weak);
  w.Int("pd_unobserved", l.pd_unobserved).Int("nd_unobserved", l.nd_unobserved);
  w.Int("nd_residue", l.nd_residue).Int("pd_residue", l.pd_residue).Number("seconds", l.seconds);
  w.BeginArray("new_keyframes");
  for (const int k : new_keyframes) w.Int(k);
  w.EndArray().EndObject();
}

void WriteStageReport(const std::string& path, const StageReport& rep, const std::vector<std::size_t>& keyframes,
                      int threads) {
  io::json::Writer w;
  w.BeginObject().String("stage", "removert").BeginArray("sessions");
  for (std::size_t s = 0; s < rep.hd.size(); ++s) WriteHdJson(w, rep.sessions[s], keyframes[s], rep.hd[s]);
  w.EndArray().BeginArray("pairs");
  for (std::size_t p = 0; p < rep.ld.size(); ++p)
    WritePairJson(w, rep.pairs[p].first, rep.pairs[p].second, rep.ld[p], rep.new_keyframes[p]);
  w.EndArray().Number("seconds", rep.seconds).Int("peak_rss_bytes", rep.peak_rss_bytes);
  w.Int("threads", threads).EndObject();
  io::WriteFileAtomic(path, [&](std::ostream& os) { os << w.str(); });
}

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

StageReport RunRemovertStage(const RemovertConfig& user_cfg, const std::vector<std::string>& session_dirs,
                             const std::vector<std::string>& poses_files, const std::string& out_dir,
                             int threads) {
  user_cfg.Validate();
  const auto t0 = std::chrono::steady_clock::now();
  if (session_dirs.empty()) throw Error("removert: no sessions given");
  if (poses_files.size() != session_dirs.size())
    throw Error("removert: " + std::to_string(session_dirs.size()) + " sessions but " +
                std::to_string(poses_files.size()) + " pose files");
  io::MakeWritableDir(out_dir);
  // The whole output is built in a fresh folder and replaces out_dir when complete, so no
  // session or pair folder, or keyframe, of an earlier run survives.
  io::StagingDir staging(out_dir, "report.json");
  const std::string& out = staging.path();
  StageReport rep;
  const std::size_t ns = session_dirs.size();
  std::vector<SessionData> sd(ns);
  std::vector<std::size_t> keyframes(ns);
  for (std::size_t s = 0; s < ns; ++s) {
    sd[s].kfs = LoadWorldKeyframes(session_dirs[s], poses_files[s], &sd[s].name);
    rep.sessions.push_back(sd[s].name);
    keyframes[s] = sd[s].kfs.size();
  }
  // One sensor for every session (the central session's scans when estimated).
  const RemovertConfig cfg = WithSensor(user_cfg, sd[0].kfs, threads);
  for (std::size_t q = 1; q < ns; ++q) rep.pairs.emplace_back(PairCentral(cfg, int(q)), int(q));

  if (cfg.tiles_stage) {  // memory bounded by the tile, not the sessions (stage_tiles.cpp)
    std::vector<std::string> names;
    std::vector<std::vector<WorldKeyframe>> kfs;
    for (const SessionData& d : sd) names.push_back(d.name), kfs.push_back(d.kfs);
    detail::RunStageFromTiles(cfg, session_dirs, poses_files, names, kfs, out, threads, &rep);
  }
  // Sessions in order: HD removal of session s, then the pairs whose query is s (their central
  // came earlier). A session's maps are freed as soon as no later pair needs them, so memory
  // holds at most two sessions' maps (central + current query), not all N.
  for (std::size_t s = 0; s < ns && !cfg.tiles_stage; ++s) {
    rep.hd.push_back(RemoveSessionHd(sd[s], int(s), io::layout::SessionChangesDir(out, sd[s].name), cfg, threads));
    for (const auto& [c, q] : rep.pairs) {
      if (std::size_t(q) != s) continue;
      auto [stats, new_idx] = DetectPair(sd[std::size_t(c)], sd[s], c, q, out + "/" + io::layout::PairDirName(c, q),
                                         cfg, threads);
      rep.ld.push_back(stats);
      rep.new_keyframes.push_back(std::move(new_idx));
    }
    for (std::size_t t = 0; t <= s; ++t) {
      bool needed = false;
      for (const auto& [c, q] : rep.pairs) needed = needed || (std::size_t(c) == t && std::size_t(q) > s);
      if (!needed) sd[t].static_map = sd[t].hd_map = PointCloud();
    }
  }
  rep.seconds = Since(t0);
  rep.peak_rss_bytes = PeakRssBytes();
  WriteStageReport(out + "/report.json", rep, keyframes, threads);
  staging.Publish();
  return rep;
}

StageReport AddToRemovertStage(const RemovertConfig& user_cfg, const std::vector<std::string>& session_dirs,
                               const std::vector<std::string>& poses_files, const std::string& changes_dir,
                               int threads) {
  user_cfg.Validate();
  const auto t0 = std::chrono::steady_clock::now();
  if (session_dirs.size() < 2 || poses_files.size() != session_dirs.size())
    throw Error("removert add: need the run's sessions and the new one (last), each with a pose file");
  if (!fs::exists(changes_dir + "/report.json"))
    throw Error(changes_dir + ": no LT-removert output here (report.json missing): run the batch first");
  const int qi = int(session_dirs.size()) - 1, ci = PairCentral(user_cfg, qi);
  SessionData central, c, q;
  central.kfs = LoadWorldKeyframes(session_dirs[0], poses_files[0], &central.name);
  const RemovertConfig cfg = WithSensor(user_cfg, central.kfs, threads);  // as the batch: the central's sensor
  c.kfs = ci == 0 ? std::move(central.kfs) : LoadWorldKeyframes(session_dirs[std::size_t(ci)],
                                                                poses_files[std::size_t(ci)], &c.name);
  if (ci == 0) c.name = central.name;
  q.kfs = LoadWorldKeyframes(session_dirs.back(), poses_files.back(), &q.name);
  // The earlier session's HD removal is read from its output, never redone.
  const std::string cdir = io::layout::SessionChangesDir(changes_dir, c.name);
  c.static_map = io::ReadPcd(io::layout::StaticMapIn(cdir));
  c.hd_map = io::ReadPcd(io::layout::HdMapIn(cdir));

  io::StagingDir session_out(io::layout::SessionChangesDir(changes_dir, q.name),
                             fs::path(io::layout::StaticMapIn(".")).filename().string());
  io::StagingDir pair_out(changes_dir + "/" + io::layout::PairDirName(ci, qi), "keyframes.csv");
  StageReport rep;
  rep.sessions = {q.name};
  rep.hd.push_back(RemoveSessionHd(q, qi, session_out.path(), cfg, threads));
  auto [stats, new_idx] = DetectPair(c, q, ci, qi, pair_out.path(), cfg, threads);
  rep.pairs.emplace_back(ci, qi);
  rep.ld.push_back(stats);
  rep.new_keyframes.push_back(std::move(new_idx));
  rep.seconds = Since(t0);
  rep.peak_rss_bytes = PeakRssBytes();
  WriteStageReport(session_out.path() + "/report.json", rep, {q.kfs.size()}, threads);
  session_out.Publish();
  pair_out.Publish();
  return rep;
}

RemovertConfig WithAlignment(const RemovertConfig& cfg, const io::RunManifest& manifest,
                             const std::vector<std::string>& names) {
  RemovertConfig out = cfg;
  out.session_rotation_sigma_deg.clear();
  const std::vector<io::ManifestSession> aligned = manifest.Aligned();
  for (const std::string& name : names) {
    const auto it = std::find_if(aligned.begin(), aligned.end(), [&](const io::ManifestSession& s) { return s.name == name; });
    double sigma = std::numeric_limits<double>::quiet_NaN();  // not in the run, or not measured
    if (it == aligned.begin())
      sigma = 0.0;  // the run's central: the others are measured against it
    else if (it != aligned.end() && it->rotation_sigma_deg > 0.0)
      sigma = it->rotation_sigma_deg;
    out.session_rotation_sigma_deg.push_back(sigma);
  }
  return out;
}

RunSessions SessionsOfRun(const io::RunManifest& manifest, const std::string& aligned_dir) {
  RunSessions out;
  for (const auto& s : manifest.Aligned()) {
    out.dirs.push_back(s.dir);
    out.poses.push_back(io::layout::PosesWorldFile(aligned_dir, s.name));
    out.names.push_back(s.name);
  }
  return out;
}

StageReport RunRemovertStageOnRun(const RemovertConfig& cfg, const std::string& aligned_dir,
                                  const std::string& out_dir, int threads) {
  const io::RunManifest m = io::ReadRunManifest(aligned_dir);
  const RunSessions run = SessionsOfRun(m, aligned_dir);
  return RunRemovertStage(WithAlignment(cfg, m, run.names), run.dirs, run.poses, out_dir, threads);
}

}  // namespace ltm::removert
