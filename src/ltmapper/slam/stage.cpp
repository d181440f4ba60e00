// The LT-SLAM stage from files: load session directories, align, write aligned/ (see
// docs/FORMATS.md, "LT-SLAM output").
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/slam.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <map>
#include <ostream>
#include <set>
#include <sstream>

namespace ltm::slam {

namespace {
namespace fs = std::filesystem;

// A pose as its 3 x 4 matrix, row by row, under `key`.
void PoseJson(io::json::Writer& w, const std::string& key, const Pose& T) {
  w.BeginArray(key);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) w.Number(T.matrix()(r, c));
  w.EndArray();
}

double YawDeg(const Pose& T) {
  return std::atan2(T.linear()(1, 0), T.linear()(0, 0)) * 180.0 / M_PI;
}

// joint.g2o: every aligned session's keyframes in world coordinates and the accepted loops.
void WriteJointGraph(const std::vector<Session>& sessions, const SlamResult& res, const std::string& out_dir) {
  const std::size_t n = sessions.size();
  // Vertex id = number of
  // keyframes of all earlier aligned sessions + position in the session (no digit tricks).
  io::G2oGraph graph;
  std::vector<int> offset(n, -1);
  int next = 0;
  for (std::size_t s = 0; s < n; ++s) {
    if (!res.sessions[s].aligned) continue;
    offset[s] = next;
    for (const Pose& T : res.sessions[s].T_world_sensor) graph.vertices.push_back({next++, T});
  }
  for (std::size_t s = 0; s < n; ++s) {
    if (offset[s] < 0) continue;
    for (const auto* edges : {&sessions[s].odometry, &sessions[s].loops, &res.sessions[s].registered}) {
      for (Edge e : *edges) {
        e.from = offset[s] + sessions[s].Find(e.from);
        e.to = offset[s] + sessions[s].Find(e.to);
        graph.edges.push_back(e);
      }
    }
  }
  for (const LoopRecord& l : res.loops) {
    if (!l.accepted) continue;
    Edge e;
    e.from = offset[l.a.session] + l.a.keyframe;
    e.to = offset[l.b.session] + l.b.keyframe;
    e.T_from_to = l.T_a_b;
    e.information = l.information;
    e.has_information = true;
    graph.edges.push_back(e);
  }
  io::WriteG2o((fs::path(out_dir) / "joint.g2o").string(), graph);

}

// loops.csv: every candidate loop with its registration and outcome.
void WriteLoopsCsv(const std::vector<Session>& sessions, const SlamResult& res, const std::string& out_dir) {
  io::WriteFileAtomic((fs::path(out_dir) / "loops.csv").string(), [&](std::ostream& os) {
    os << "pair,kf_a,kf_b,source,sc_dist,yaw_deg,fitness,inlier_ratio,inlier_rms_m,accepted,"
          "residual_t_m,residual_r_deg,tx,ty,tz,qx,qy,qz,qw,view,status\n";
    os << std::setprecision(6);
    for (const LoopRecord& l : res.loops) {
      const Session& A = sessions[l.a.session];
      const Session& B = sessions[l.b.session];
      os << A.name << "-" << B.name << "," << A.keyframes[l.a.keyframe].index << ","
         << B.keyframes[l.b.keyframe].index << "," << l.source << "," << l.sc_distance << ","
         << l.yaw_deg << "," << l.fitness << "," << l.overlap << "," << l.inlier_rms_m << ","
         << (l.accepted ? 1 : 0) << "," << l.residual_t_m
         << "," << l.residual_r_deg << ",";
      const Eigen::Quaterniond q(l.T_a_b.linear());
      const Eigen::Vector3d t = l.T_a_b.translation();
      os << t.x() << "," << t.y() << "," << t.z() << "," << q.x() << "," << q.y() << "," << q.z()
         << "," << q.w() << "," << l.view << ",\"" << l.status << "\"\n";
    }
  });

}

// report.json's record of session s.
void SessionJson(io::json::Writer& w, const Session& session, const SessionAlignment& a) {
  w.BeginObject().String("name", a.name).String("dir", session.dir).Int("keyframes", session.keyframes.size());
  w.Bool("aligned", a.aligned).String("reason", a.reason).Int("sc_candidates", a.sc_candidates);
  w.Int("loops_verified", a.loops_verified).Int("loops_accepted", a.loops_accepted);
  w.Int("radius_loops_accepted", a.radius_loops).Int("own_loops_accepted", a.own_loops);
  w.Int("registered_steps", a.registered.size());
  if (a.aligned)
    PoseJson(w, "anchor", a.anchor);
  else
    w.Null("anchor");
  w.EndObject();
}

// report.json: per-session alignment, solver and timing figures.
void WriteReportJson(const std::vector<Session>& sessions, const SlamResult& res, const std::string& out_dir, const SlamConfig& cfg) {
  bool all = true;
  for (const auto& a : res.sessions) all = all && a.aligned;
  io::json::Writer w;
  w.BeginObject().String("central", res.sessions[0].name).Bool("given_poses", res.given_poses).Bool("all_aligned", all);
  w.BeginArray("sessions");
  for (std::size_t s = 0; s < sessions.size(); ++s) SessionJson(w, sessions[s], res.sessions[s]);
  w.EndArray();
  w.Int("registrations", res.registrations).Number("refine_radius_m", res.refine_radius_m);
  w.Number("max_translation_m", res.max_translation_m);
  w.BeginObject("solver").Bool("usable", res.solution_usable).Number("initial_cost", res.initial_cost);
  w.Number("final_cost", res.final_cost).Int("iterations", res.solver_iterations).EndObject();
  w.BeginObject("time_s").Number("descriptors", res.time_descriptors_s).Number("retrieval", res.time_retrieval_s);
  w.Number("registration", res.time_registration_s).Number("optimisation", res.time_optimisation_s);
  w.Number("total", res.time_total_s).EndObject();
  w.String("robust_loss", cfg.robust_loss).Int("peak_rss_bytes", PeakRssBytes()).EndObject();
  io::WriteFileAtomic((fs::path(out_dir) / "report.json").string(), [&](std::ostream& os) { os << w.str(); });
}

// report.md: the same for a reader.
void WriteReportMd(const std::vector<Session>& sessions, const SlamResult& res, const std::string& out_dir) {
  const std::size_t n = sessions.size();
  io::WriteFileAtomic((fs::path(out_dir) / "report.md").string(), [&](std::ostream& os) {
    os << std::fixed << std::setprecision(2) << "# LT-SLAM report\n\nCentral session: `"
       << res.sessions[0].name << "` (world frame).\n\n"
       << (res.given_poses ? "Poses given (`--poses`): every session placed as given, not aligned; the radius loops "
                             "only measure the given poses (the rotation error LD's tolerances follow).\n\n"
                           : "")
       << "| session | keyframes | registered steps | aligned | SC candidates | verified | accepted | radius | own loops | "
          "anchor x y z [m] | anchor yaw [deg] |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (std::size_t s = 0; s < n; ++s) {
      const auto& a = res.sessions[s];
      os << "| " << a.name << " | " << sessions[s].keyframes.size() << " | " << a.registered.size() << " | "
         << (a.aligned ? "yes" : "**NOT ALIGNED**") << " | " << a.sc_candidates << " | "
         << a.loops_verified << " | " << a.loops_accepted << " | " << a.radius_loops << " | " << a.own_loops << " | ";
      if (a.aligned) {
        os << a.anchor.translation().x() << " " << a.anchor.translation().y() << " "
           << a.anchor.translation().z() << " | " << YawDeg(a.anchor) << " |\n";
      } else {
        os << "- | - |\n";
      }
    }
    for (const auto& a : res.sessions) {
      if (!a.aligned) os << "\n**" << a.name << " is not aligned**: " << a.reason << "\n";
    }
    os << "\nKeyframes of one session overlap enough to pass verification up to " << res.refine_radius_m
       << " m apart (median; the radius search's radius) and " << res.max_translation_m
       << " m at most (no registration may move a candidate farther).\n";
    os << "\nTime: descriptors " << res.time_descriptors_s << " s, retrieval "
       << res.time_retrieval_s << " s, registration " << res.time_registration_s << " s ("
       << res.registrations << " GICP), optimisation " << res.time_optimisation_s << " s, total "
       << res.time_total_s << " s.\n";
  });
}

void WriteOutputs(const std::vector<Session>& sessions, const SlamResult& res,
                  const SlamConfig& cfg, const std::string& out_dir) {
  io::MakeDirs(out_dir);
  const std::size_t n = sessions.size();
  // ---- per session (out_dir is fresh (StagingDir): no world poses of an earlier run are left)
  for (std::size_t s = 0; s < n; ++s) WriteSessionAlignment(out_dir, res.sessions[s].name, res.sessions[s]);

  WriteJointGraph(sessions, res, out_dir);
  WriteLoopsCsv(sessions, res, out_dir);
  WriteReportJson(sessions, res, out_dir, cfg);
  WriteReportMd(sessions, res, out_dir);
}
void WriteManifest(const std::vector<Session>& sessions, const std::vector<std::string>& session_dirs,
                   const SlamResult& res, const SlamConfig& cfg, const std::string& out_dir) {
  io::RunManifest m;
  for (std::size_t s = 0; s < sessions.size(); ++s) {
    const SessionAlignment& a = res.sessions[s];
    m.sessions.push_back({a.name, fs::absolute(session_dirs[s]).lexically_normal().string(), a.aligned,
                          a.aligned ? std::string() : a.reason, a.aligned ? a.rotation_sigma_deg : 0.0});
  }
  m.slam_config = ConfigToString(cfg);
  io::WriteRunManifest(out_dir, m);
}
// The session directories, named (a session without a name takes its folder's), names unique.
std::vector<Session> LoadSessions(const std::vector<std::string>& session_dirs) {
  std::vector<Session> sessions;
  std::set<std::string> names;
  for (const auto& dir : session_dirs) {
    sessions.push_back(io::LoadSession(dir));
    Session& s = sessions.back();
    if (s.name.empty()) s.name = fs::path(dir).filename().string();
    if (!names.insert(s.name).second) {
      throw Error(dir + ": two sessions share the name '" + s.name +
                  "' (output folders are named after sessions)");
    }
    spdlog::info("slam: session {} ({}): {} keyframes, {} odometry + {} loop edges", s.name, dir,
                 s.keyframes.size(), s.odometry.size(), s.loops.size());
  }
  return sessions;
}

}  // namespace

SessionAlignment GivenAlignment(const Session& s, const std::string& file) {
  SessionAlignment a;
  a.name = s.name;
  a.aligned = true;
  a.T_world_sensor = io::ReadKittiPoses(file);
  if (a.T_world_sensor.size() != s.keyframes.size())
    throw Error(file, 0, std::to_string(a.T_world_sensor.size()) + " poses for the " +
                             std::to_string(s.keyframes.size()) + " keyframes of session '" + s.name + "' (" +
                             s.dir + ")");
  for (const Keyframe& k : s.keyframes) a.T_session_sensor.push_back(k.T_session_sensor);
  if (!s.keyframes.empty()) a.anchor = a.T_world_sensor.front() * a.T_session_sensor.front().inverse();
  return a;
}

GivenPoses ReadGivenPoses(const std::vector<std::string>& session_dirs, const std::vector<std::string>& pose_files) {
  if (session_dirs.empty()) throw Error("slam: no session directories given");
  if (pose_files.size() != session_dirs.size())
    throw Error("slam: " + std::to_string(session_dirs.size()) + " sessions but " +
                std::to_string(pose_files.size()) + " pose files (one per session, in the same order)");
  GivenPoses g;
  g.session_dirs = session_dirs;
  g.sessions = LoadSessions(session_dirs);
  for (std::size_t s = 0; s < g.sessions.size(); ++s) g.placed.sessions.push_back(GivenAlignment(g.sessions[s], pose_files[s]));
  return g;
}

SlamResult WriteGivenPoses(const SlamConfig& cfg, GivenPoses given, const std::string& out_dir, int threads) {
  io::MakeWritableDir(out_dir);
  io::StagingDir staging(out_dir, "report.json");
  SlamResult& res = given.placed;
  MeasureGivenPoses(given.sessions, res, cfg, threads);
  WriteOutputs(given.sessions, res, cfg, staging.path());
  WriteManifest(given.sessions, given.session_dirs, res, cfg, staging.path());
  staging.Publish();
  spdlog::info("slam: {} sessions placed by the given world poses (no alignment)", given.sessions.size());
  return res;
}

SlamResult RunSlamStage(const SlamConfig& cfg, const std::vector<std::string>& session_dirs,
                        const std::string& out_dir, int threads) {
  if (session_dirs.empty()) throw Error("slam: no session directories given");
  io::MakeWritableDir(out_dir);  // before minutes of alignment, not after
  // The whole output is built in a fresh folder and replaces out_dir when complete.
  io::StagingDir staging(out_dir, "report.json");
  const std::vector<Session> sessions = LoadSessions(session_dirs);
  SlamResult res = AlignSessions(sessions, cfg, threads);
  WriteOutputs(sessions, res, cfg, staging.path());
  WriteManifest(sessions, session_dirs, res, cfg, staging.path());
  staging.Publish();
  for (const auto& a : res.sessions) {
    if (a.aligned) {
      spdlog::info("slam: {} aligned: {} loops accepted ({} radius), {} within itself, anchor t = [{:.2f} {:.2f} "
                   "{:.2f}] m, yaw {:.2f} deg",
                   a.name, a.loops_accepted, a.radius_loops, a.own_loops, a.anchor.translation().x(),
                   a.anchor.translation().y(), a.anchor.translation().z(), YawDeg(a.anchor));
    } else {
      spdlog::warn("slam: {} is NOT aligned: {}", a.name, a.reason);
    }
  }
  return res;
}

}  // namespace ltm::slam
