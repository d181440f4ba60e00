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

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <set>
#include <sstream>

namespace ltm::removert {
namespace {

namespace fs = std::filesystem;

std::string Index6(int index) { return io::layout::KeyframeDirName(index); }

PointCloud Positions(const std::vector<WorldKeyframe>& kfs) {
  PointCloud c;
  for (const auto& kf : kfs) {
    const Eigen::Vector3d t = kf.T_world_sensor.translation();
    c.push_back(float(t.x()), float(t.y()), float(t.z()));
  }
  return c;
}

// Nearest keyframe (position index) of every point.
std::vector<std::uint32_t> Nearest(const PointCloud& pts, const geometry::KdTree& tree, int threads,
                                   std::vector<float>* sq_dist = nullptr) {
  std::vector<std::uint32_t> out(pts.size(), 0);
  if (sq_dist) sq_dist->assign(pts.size(), 0.f);
  const std::size_t chunk = 8192;
  detail::ParallelFor((pts.size() + chunk - 1) / chunk, threads, [&](std::size_t c) {
    const std::size_t b = c * chunk, e = std::min(pts.size(), b + chunk);
    for (std::size_t i = b; i < e; ++i) {
      std::uint32_t k = 0;
      float d2 = 0.f;
      tree.Nearest(pts.points[i].xyz(), &k, &d2);
      out[i] = k;
      if (sq_dist) (*sq_dist)[i] = d2;
    }
  });
  return out;
}

// Member indices per bucket.
std::vector<std::vector<std::uint32_t>> Buckets(const std::vector<std::uint32_t>& owner, std::size_t n) {
  std::vector<std::vector<std::uint32_t>> b(n);
  for (std::size_t i = 0; i < owner.size(); ++i)
    if (owner[i] < n) b[owner[i]].push_back(std::uint32_t(i));
  return b;
}

PointCloud Voxel(const PointCloud& c, double voxel_m) {
  return voxel_m > 0.0 ? geometry::VoxelDownsample(c, voxel_m, 1) : c;
}

// One cloud of a keyframe folder: file name (without .pcd), world-frame points, class and session.
struct KeyframePart {
  const char* name;
  PointCloud cloud;
  PointClass cls;
  int session;
};

// The parts in the keyframe's local frame as PCDs, and with a class field in classes.ply.
void WriteKeyframeDir(const std::string& dir, const Pose& T_world_sensor, const std::vector<KeyframePart>& parts,
                      const RemovertConfig& cfg) {
  io::MakeDirs(dir);
  std::vector<PointCloud> local(parts.size());
  std::vector<io::PlyPart> ply;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    local[p] = Voxel(detail::ToLocal(parts[p].cloud, T_world_sensor), cfg.keyframe_voxel_m);
    io::WritePcd(dir + "/" + parts[p].name + ".pcd", local[p]);
    ply.push_back({&local[p], parts[p].cls, std::uint16_t(parts[p].session)});
  }
  if (cfg.write_ply) io::WritePly(dir + "/classes.ply", ply);
}

std::string JsonStr(const std::string& s) {
  std::string o = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') o += '\\';
    o += ch;
  }
  return o + "\"";
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
  std::vector<std::vector<WorldKeyframe>> kfs(ns);
  for (std::size_t s = 0; s < ns; ++s) {
    const Session sess = io::LoadSession(session_dirs[s]);
    const std::vector<Pose> poses = io::ReadKittiPoses(poses_files[s]);
    if (poses.size() != sess.keyframes.size())
      throw Error(poses_files[s], 0,
                  std::to_string(poses.size()) + " poses but session " + session_dirs[s] + " has " +
                      std::to_string(sess.keyframes.size()) + " keyframes (one pose per keyframe, in order)");
    rep.sessions.push_back(sess.name.empty() ? fs::path(session_dirs[s]).filename().string() : sess.name);
    for (std::size_t k = 0; k < poses.size(); ++k) {
      WorldKeyframe w;
      w.index = sess.keyframes[k].index;
      w.T_world_sensor = poses[k];
      w.cloud = sess.keyframes[k].cloud;
      w.cloud_path = sess.keyframes[k].cloud_path;
      kfs[s].push_back(std::move(w));
    }
  }
  // One sensor for every session (the central session's scans when estimated).
  const RemovertConfig cfg = WithSensor(user_cfg, kfs[0]);

  // Pairs: (central 0, q) for every query, or consecutive (q-1, q).
  for (std::size_t q = 1; q < ns; ++q) {
    const int c = cfg.pairs == "consecutive" ? int(q) - 1 : 0;
    rep.pairs.emplace_back(c, int(q));
  }

  // ---- HD removal of one session: its HD-free and HD maps stay in memory while a pair needs them.
  std::vector<PointCloud> static_maps(ns), hd_maps(ns);
  auto remove_hd = [&](std::size_t s) {
    spdlog::info("removert: HD removal of {} ({} keyframes)", rep.sessions[s], kfs[s].size());
    HdResult hd;
    try {
      hd = RemoveHd(kfs[s], cfg, threads);
    } catch (const Error& e) {  // name the session: an empty scan rejects it, as LT-SLAM does
      throw Error("removert: session '" + rep.sessions[s] + "': " + e.what());
    }
    const HdStats& st = hd.stats;
    spdlog::info("removert: {}: map {} points, candidates {}, reverted {}, removed {} + {} dilated ({:.2f} %), "
                 "{:.1f} s map + {:.1f} s votes",
                 rep.sessions[s], st.map_points, st.candidates, st.reverted, st.removed, st.dilated,
                 st.map_points ? 100.0 * double(st.removed + st.dilated) / double(st.map_points) : 0.0,
                 st.seconds_map, st.seconds_votes);
    const std::string dir = io::layout::SessionChangesDir(out, rep.sessions[s]);
    io::MakeDirs(dir);
    io::WritePcd(io::layout::StaticMapFile(out, rep.sessions[s]), hd.static_map);
    io::WritePcd(dir + "/hd_map.pcd", hd.hd_map);
    if (cfg.write_ply) {
      const auto ses = std::uint16_t(s);
      io::WritePly(dir + "/map.ply", {{&hd.static_map, PointClass::kStatic, ses},
                                      {&hd.hd_map, PointClass::kHD, ses}});
    }
    rep.hd.push_back(st);
    static_maps[s] = std::move(hd.static_map);
    hd_maps[s] = std::move(hd.hd_map);
  };

  // ---- LD of one pair.
  auto detect_ld = [&](int c, int q) {
    const std::string pname = io::layout::PairDirName(c, q);
    spdlog::info("removert: LD {} vs {}", rep.sessions[std::size_t(c)], rep.sessions[std::size_t(q)]);
    const LdResult ld = DetectLd(static_maps[std::size_t(c)], static_maps[std::size_t(q)],
                                 kfs[std::size_t(c)], kfs[std::size_t(q)], cfg, threads);
    spdlog::info("removert: {}: ND strong {} weak {} (unobserved {}), PD strong {} weak {} "
                 "(unobserved {}) ({:.1f} s)",
                 pname, ld.stats.nd_strong, ld.stats.nd_weak, ld.stats.nd_unobserved,
                 ld.stats.pd_strong, ld.stats.pd_weak, ld.stats.pd_unobserved, ld.stats.seconds);
    rep.ld.push_back(ld.stats);
    const std::string dir = out + "/" + pname;
    io::MakeDirs(dir);
    io::WritePcd(dir + "/pd_strong.pcd", ld.pd_strong);
    io::WritePcd(dir + "/pd_weak.pcd", ld.pd_weak);
    io::WritePcd(dir + "/nd_strong.pcd", ld.nd_strong);
    io::WritePcd(dir + "/nd_weak.pcd", ld.nd_weak);
    io::WritePcd(dir + "/pd_unobserved.pcd", ld.pd_unobserved);
    // Keyframe clouds: new territory (query points the central never had in view) is added to
    // the map like strong PD, so LT-map's composition brings it in.
    PointCloud pd_strong_kf = ld.pd_strong;
    pd_strong_kf.append(ld.pd_unobserved);

    // Central static minus ND.
    const PointCloud& cmap = static_maps[std::size_t(c)];
    if (cfg.write_ply) {
      std::vector<bool> unchanged(cmap.size());
      for (std::size_t i = 0; i < cmap.size(); ++i) unchanged[i] = !ld.central_nd[i];
      const auto cs = std::uint16_t(c), qs = std::uint16_t(q);
      constexpr std::int32_t kNoObject = -1, kNewTerritory = 1;  // object field of changes.ply
      io::WritePly(dir + "/changes.ply", {{&cmap, PointClass::kStatic, cs, kNoObject, &unchanged},
                                          {&ld.nd_strong, PointClass::kNDStrong, cs},
                                          {&ld.nd_weak, PointClass::kNDWeak, cs},
                                          {&ld.pd_strong, PointClass::kPDStrong, qs},
                                          {&ld.pd_weak, PointClass::kPDWeak, qs},
                                          {&ld.pd_unobserved, PointClass::kPDStrong, qs, kNewTerritory}});
    }

    // ---- Keyframe assignment (rule at the top of this file).
    const auto& ckf = kfs[std::size_t(c)];
    const auto& qkf = kfs[std::size_t(q)];
    const std::size_t nc = ckf.size();
    const geometry::KdTree ctree(Positions(ckf));
    const geometry::KdTree qtree(Positions(qkf));
    std::vector<float> qd2;
    Nearest(Positions(qkf), ctree, threads, &qd2);
    std::vector<std::uint32_t> new_q;  // query keyframe positions that become new keyframes
    const float nk2 = float(cfg.new_keyframe_dist_m * cfg.new_keyframe_dist_m);
    for (std::size_t j = 0; j < qkf.size(); ++j)
      if (qd2[j] > nk2) new_q.push_back(std::uint32_t(j));
    PointCloud cand = Positions(ckf);
    for (auto j : new_q) cand.push_back(float(qkf[j].T_world_sensor.translation().x()),
                                         float(qkf[j].T_world_sensor.translation().y()),
                                         float(qkf[j].T_world_sensor.translation().z()));
    const geometry::KdTree cand_tree(cand);
    // PD owner: [0, nc) central keyframe, nc + j query keyframe j.
    auto pd_owner = [&](const PointCloud& pd, std::vector<std::uint32_t>* owner) {
      std::vector<float> d2;
      *owner = Nearest(pd, cand_tree, threads, &d2);
      const float ar2 = float(cfg.assign_radius_m * cfg.assign_radius_m);
      for (std::size_t i = 0; i < pd.size(); ++i) {
        std::uint32_t& o = (*owner)[i];
        if (o >= nc) {
          o = std::uint32_t(nc) + new_q[o - nc];
        } else if (d2[i] > ar2) {
          std::uint32_t j = 0;
          float dq = 0.f;
          qtree.Nearest(pd.points[i].xyz(), &j, &dq);
          o = std::uint32_t(nc) + j;
        }
      }
    };
    std::vector<std::uint32_t> own_pds, own_pdw;
    pd_owner(pd_strong_kf, &own_pds);
    pd_owner(ld.pd_weak, &own_pdw);
    const std::size_t nk = nc + qkf.size();
    const auto b_static = Buckets(Nearest(cmap, ctree, threads), nk);
    const auto b_hd = Buckets(Nearest(hd_maps[std::size_t(c)], ctree, threads), nk);
    const auto b_nds = Buckets(Nearest(ld.nd_strong, ctree, threads), nk);
    const auto b_ndw = Buckets(Nearest(ld.nd_weak, ctree, threads), nk);
    const auto b_pds = Buckets(own_pds, nk);
    const auto b_pdw = Buckets(own_pdw, nk);
    std::vector<int> is_new(qkf.size(), 0);
    for (std::size_t j = 0; j < qkf.size(); ++j)
      if (!b_pds[nc + j].empty() || !b_pdw[nc + j].empty()) is_new[j] = 1;
    for (auto j : new_q) is_new[j] = 1;
    std::vector<int> new_list;
    for (std::size_t j = 0; j < qkf.size(); ++j)
      if (is_new[j]) new_list.push_back(int(j));

    auto pick = [](const PointCloud& cl, const std::vector<std::uint32_t>& idx) { return cl.select(idx); };
    if (cfg.write_keyframes) {
      detail::ParallelFor(nc, threads, [&](std::size_t k) {
        WriteKeyframeDir(dir + "/keyframes/" + Index6(ckf[k].index), ckf[k].T_world_sensor,
                         {{"static", pick(cmap, b_static[k]), PointClass::kStatic, c},
                          {"hd", pick(hd_maps[std::size_t(c)], b_hd[k]), PointClass::kHD, c},
                          {"pd_strong", pick(pd_strong_kf, b_pds[k]), PointClass::kPDStrong, q},
                          {"pd_weak", pick(ld.pd_weak, b_pdw[k]), PointClass::kPDWeak, q},
                          {"nd_strong", pick(ld.nd_strong, b_nds[k]), PointClass::kNDStrong, c},
                          {"nd_weak", pick(ld.nd_weak, b_ndw[k]), PointClass::kNDWeak, c}},
                         cfg);
      });
      detail::ParallelFor(new_list.size(), threads, [&](std::size_t t) {
        const std::size_t j = std::size_t(new_list[t]);
        WriteKeyframeDir(dir + "/new_keyframes/" + Index6(qkf[j].index), qkf[j].T_world_sensor,
                         {{"pd_strong", pick(pd_strong_kf, b_pds[nc + j]), PointClass::kPDStrong, q},
                          {"pd_weak", pick(ld.pd_weak, b_pdw[nc + j]), PointClass::kPDWeak, q}},
                         cfg);
      });
    }
    // Keyframe list: kind, session, index, point counts, world pose (KITTI 12 numbers).
    io::WriteFileAtomic(dir + "/keyframes.csv", [&](std::ostream& os) {
      os << "kind,session,index,static,hd,pd_strong,pd_weak,nd_strong,nd_weak,"
            "r00,r01,r02,tx,r10,r11,r12,ty,r20,r21,r22,tz\n";
      os << std::setprecision(9);
      auto row = [&](const char* kind, int ses, const WorldKeyframe& kf, std::size_t a, std::size_t b,
                     std::size_t c2, std::size_t d, std::size_t e, std::size_t f) {
        os << kind << ',' << ses << ',' << kf.index << ',' << a << ',' << b << ',' << c2 << ',' << d
           << ',' << e << ',' << f;
        const Eigen::Matrix4d M = kf.T_world_sensor.matrix();
        for (int r = 0; r < 3; ++r)
          for (int cc = 0; cc < 4; ++cc) os << ',' << M(r, cc);
        os << '\n';
      };
      for (std::size_t k = 0; k < nc; ++k)
        row("central", c, ckf[k], b_static[k].size(), b_hd[k].size(), b_pds[k].size(),
            b_pdw[k].size(), b_nds[k].size(), b_ndw[k].size());
      for (int j : new_list)
        row("new", q, qkf[std::size_t(j)], 0, 0, b_pds[nc + std::size_t(j)].size(),
            b_pdw[nc + std::size_t(j)].size(), 0, 0);
    });
    std::vector<int> new_idx;
    for (int j : new_list) new_idx.push_back(qkf[std::size_t(j)].index);
    rep.new_keyframes.push_back(new_idx);
  };

  // Sessions in order: HD removal of session s, then the pairs whose query is s (their central
  // came earlier). A session's maps are freed as soon as no later pair needs them, so memory
  // holds at most two sessions' maps (central + current query), not all N.
  for (std::size_t s = 0; s < ns; ++s) {
    remove_hd(s);
    for (const auto& [c, q] : rep.pairs)
      if (std::size_t(q) == s) detect_ld(c, q);
    for (std::size_t t = 0; t <= s; ++t) {
      bool needed = false;
      for (const auto& [c, q] : rep.pairs) needed = needed || (std::size_t(c) == t && std::size_t(q) > s);
      if (!needed) {
        static_maps[t] = PointCloud();
        hd_maps[t] = PointCloud();
      }
    }
  }

  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  rep.peak_rss_bytes = PeakRssBytes();

  io::WriteFileAtomic(out + "/report.json", [&](std::ostream& os) {
    os << std::setprecision(9) << "{\n  \"stage\": \"removert\",\n  \"sessions\": [\n";
    for (std::size_t s = 0; s < ns; ++s) {
      const HdStats& h = rep.hd[s];
      os << "    {\"name\": " << JsonStr(rep.sessions[s]) << ", \"keyframes\": " << kfs[s].size()
         << ", \"map_points\": " << h.map_points << ", \"candidates\": " << h.candidates
         << ", \"reverted\": " << h.reverted << ", \"removed\": " << h.removed << ", \"dilated\": " << h.dilated
         << ", \"removed_per_resolution\": [";
      for (std::size_t l = 0; l < h.removed_per_resolution.size(); ++l)
        os << (l ? ", " : "") << h.removed_per_resolution[l];
      os << "], \"seconds_map\": " << h.seconds_map << ", \"seconds_votes\": " << h.seconds_votes
         << "}" << (s + 1 < ns ? "," : "") << "\n";
    }
    os << "  ],\n  \"pairs\": [\n";
    for (std::size_t p = 0; p < rep.pairs.size(); ++p) {
      const LdStats& l = rep.ld[p];
      os << "    {\"central\": " << rep.pairs[p].first << ", \"query\": " << rep.pairs[p].second
         << ", \"dir\": " << JsonStr(io::layout::PairDirName(rep.pairs[p].first, rep.pairs[p].second))
         << ", \"nd_strong\": " << l.nd_strong << ", \"nd_weak\": " << l.nd_weak
         << ", \"pd_strong\": " << l.pd_strong << ", \"pd_weak\": " << l.pd_weak
         << ", \"pd_unobserved\": " << l.pd_unobserved << ", \"nd_unobserved\": " << l.nd_unobserved
         << ", \"seconds\": " << l.seconds << ", \"new_keyframes\": [";
      for (std::size_t j = 0; j < rep.new_keyframes[p].size(); ++j)
        os << (j ? ", " : "") << rep.new_keyframes[p][j];
      os << "]}" << (p + 1 < rep.pairs.size() ? "," : "") << "\n";
    }
    os << "  ],\n  \"seconds\": " << rep.seconds << ",\n  \"peak_rss_bytes\": " << rep.peak_rss_bytes
       << ",\n  \"threads\": " << threads << "\n}\n";
  });
  staging.Publish();
  return rep;
}

StageReport RunRemovertStageOnRun(const RemovertConfig& cfg, const std::string& aligned_dir,
                                  const std::string& out_dir, int threads) {
  std::vector<std::string> dirs, poses;
  for (const auto& s : io::ReadRunManifest(aligned_dir).Aligned()) {
    dirs.push_back(s.dir);
    poses.push_back(io::layout::PosesWorldFile(aligned_dir, s.name));
  }
  return RunRemovertStage(cfg, dirs, poses, out_dir, threads);
}

}  // namespace ltm::removert
