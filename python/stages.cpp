// Config objects and the stages (sim, LT-SLAM, LT-removert, LT-map from files, the pipeline):
// the same library calls as apps/cmd_{sim,slam,removert,map,run}.cpp, results as dicts.
#include "bind_config.hpp"

#include "ltmapper/eval/eval.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/map/map.hpp"
#include "ltmapper/pipeline/pipeline.hpp"
#include "ltmapper/removert/removert.hpp"
#include "ltmapper/sim/sim.hpp"
#include "ltmapper/slam/slam.hpp"

#include <algorithm>
#include <filesystem>

namespace ltm::py_bind {

py::dict IntegrationToDict(const map::IntegrationResult& r);  // store.cpp

namespace {

py::dict SlamToDict(const slam::SlamResult& r) {
  py::list sessions;
  for (const auto& s : r.sessions) {
    py::dict d;
    d["name"] = s.name;
    d["aligned"] = s.aligned;
    d["reason"] = s.reason;
    d["anchor"] = PoseToNumpy(s.anchor);
    d["T_session_sensor"] = PosesToNumpy(s.T_session_sensor);
    d["T_world_sensor"] = PosesToNumpy(s.T_world_sensor);
    d["sc_candidates"] = s.sc_candidates;
    d["loops_verified"] = s.loops_verified;
    d["loops_accepted"] = s.loops_accepted;
    d["radius_loops"] = s.radius_loops;
    sessions.append(d);
  }
  py::list loops;
  for (const auto& l : r.loops) {
    py::dict d;
    d["a"] = py::make_tuple(l.a.session, l.a.keyframe);
    d["b"] = py::make_tuple(l.b.session, l.b.keyframe);
    d["source"] = l.source;
    d["sc_distance"] = l.sc_distance;
    d["yaw_deg"] = l.yaw_deg;
    d["T_a_b"] = PoseToNumpy(l.T_a_b);
    d["fitness"] = l.fitness;
    d["verified"] = l.verified;
    d["accepted"] = l.accepted;
    d["status"] = l.status;
    d["residual_t_m"] = l.residual_t_m;
    d["residual_r_deg"] = l.residual_r_deg;
    loops.append(d);
  }
  py::dict d;
  d["sessions"] = sessions;
  d["loops"] = loops;
  d["time_descriptors_s"] = r.time_descriptors_s;
  d["time_retrieval_s"] = r.time_retrieval_s;
  d["time_registration_s"] = r.time_registration_s;
  d["time_optimisation_s"] = r.time_optimisation_s;
  d["time_total_s"] = r.time_total_s;
  d["registrations"] = r.registrations;
  d["solution_usable"] = r.solution_usable;
  d["initial_cost"] = r.initial_cost;
  d["final_cost"] = r.final_cost;
  d["solver_iterations"] = r.solver_iterations;
  return d;
}

py::dict HdStatsToDict(const removert::HdStats& h) {
  py::dict d;
  d["map_points"] = h.map_points;
  d["removed_per_resolution"] = h.removed_per_resolution;
  d["candidates"] = h.candidates;
  d["reverted"] = h.reverted;
  d["removed"] = h.removed;
  d["dilated"] = h.dilated;
  d["seconds_map"] = h.seconds_map;
  d["seconds_votes"] = h.seconds_votes;
  return d;
}

py::dict LdStatsToDict(const removert::LdStats& l) {
  py::dict d;
  d["central_points"] = l.central_points;
  d["query_points"] = l.query_points;
  d["nd_strong"] = l.nd_strong;
  d["nd_weak"] = l.nd_weak;
  d["pd_strong"] = l.pd_strong;
  d["pd_weak"] = l.pd_weak;
  d["pd_unobserved"] = l.pd_unobserved;
  d["nd_unobserved"] = l.nd_unobserved;
  d["pd_same"] = l.pd_same;
  d["nd_same"] = l.nd_same;
  d["seconds"] = l.seconds;
  return d;
}

py::dict StageReportToDict(const removert::StageReport& r) {
  py::list hd, ld, pairs;
  for (const auto& h : r.hd) hd.append(HdStatsToDict(h));
  for (const auto& l : r.ld) ld.append(LdStatsToDict(l));
  for (const auto& p : r.pairs) pairs.append(py::make_tuple(p.first, p.second));
  py::dict d;
  d["sessions"] = r.sessions;
  d["hd"] = hd;
  d["pairs"] = pairs;
  d["ld"] = ld;
  d["new_keyframes"] = r.new_keyframes;
  d["seconds"] = r.seconds;
  d["peak_rss_bytes"] = r.peak_rss_bytes;
  return d;
}

py::dict SimReportToDict(const sim::SimReport& r) {
  py::list pairs;
  for (const auto& p : r.pairs) {
    py::dict d;
    d["query"] = p.query;
    d["pd_strong"] = p.pd_strong;
    d["pd_weak"] = p.pd_weak;
    d["nd_strong"] = p.nd_strong;
    d["nd_weak"] = p.nd_weak;
    d["objects_pd_strong"] = p.objects_pd_strong;
    d["objects_pd_weak"] = p.objects_pd_weak;
    d["objects_nd_strong"] = p.objects_nd_strong;
    d["objects_nd_weak"] = p.objects_nd_weak;
    d["rays"] = p.rays;
    pairs.append(d);
  }
  py::dict d;
  d["sessions"] = r.sessions;
  d["keyframes"] = r.keyframes;
  d["triangles"] = r.triangles;
  d["ld_objects"] = r.ld_objects;
  d["hd_actors"] = r.hd_actors;
  d["rays"] = r.rays;
  d["points"] = r.points;
  d["hd_points"] = r.hd_points;
  d["ld_points"] = r.ld_points;
  d["rays_per_s"] = r.rays_per_s;
  d["seconds_build"] = r.seconds_build;
  d["seconds_cast"] = r.seconds_cast;
  d["seconds_write"] = r.seconds_write;
  d["seconds_truth"] = r.seconds_truth;
  d["seconds_total"] = r.seconds_total;
  d["bytes_written"] = r.bytes_written;
  d["pairs"] = pairs;
  return d;
}

py::dict RunReportToDict(const pipeline::RunReport& r) {
  py::list stages;
  for (const auto& s : r.stages) {
    py::dict d;
    d["stage"] = s.stage;
    d["skipped"] = s.skipped;
    d["seconds"] = s.seconds;
    stages.append(d);
  }
  py::dict d;
  d["sessions"] = r.sessions;
  d["aligned"] = r.aligned;
  d["not_aligned"] = r.not_aligned;
  d["stages"] = stages;
  d["map_points_live"] = r.map_points_live;
  d["map_points_meta"] = r.map_points_meta;
  d["objects"] = r.objects;
  d["store_bytes"] = r.store_bytes;
  d["seconds"] = r.seconds;
  d["peak_rss_bytes"] = r.peak_rss_bytes;
  return d;
}

// Keyframes of a loaded session placed in the world by `poses` (one per keyframe; None: the
// session's own poses), scans read on demand from their files.
std::vector<removert::WorldKeyframe> WorldKeyframes(const Session& s, const py::object& poses) {
  std::vector<Pose> p;
  if (!poses.is_none()) {
    p = PosesFromPython(poses, "poses");
    if (p.size() != s.keyframes.size())
      throw Error(s.dir + ": " + std::to_string(s.keyframes.size()) + " keyframes but " + std::to_string(p.size()) +
                  " poses");
  }
  std::vector<removert::WorldKeyframe> out;
  for (std::size_t i = 0; i < s.keyframes.size(); ++i) {
    removert::WorldKeyframe w;
    w.index = s.keyframes[i].index;
    w.T_world_sensor = p.empty() ? s.keyframes[i].T_session_sensor : p[i];
    w.cloud = s.keyframes[i].cloud;
    w.cloud_path = s.keyframes[i].cloud_path;
    out.push_back(std::move(w));
  }
  return out;
}

std::vector<std::string> Strings(const py::object& obj) {
  if (py::isinstance<py::str>(obj)) return {py::cast<std::string>(obj)};
  std::vector<std::string> out;
  for (auto s : py::reinterpret_borrow<py::iterable>(obj)) out.push_back(py::cast<std::string>(py::str(s)));
  return out;
}

}  // namespace

void BindStages(py::module_& m) {
  // ------------------------------------------------------------------------------ configs
  BindConfig<sim::SimConfig>(m, "SimConfig", "Simulator parameters (config/params_sim.yaml).",
                             [](const sim::SimConfig& c, const std::string& w) { sim::CheckConfig(c, w); })
      .def_static("tiny", &sim::TinyConfig, "The tiny test scenario (16 beams x 360 columns, 2 sessions x 15 keyframes).");
  BindConfig<slam::SlamConfig>(m, "SlamConfig", "LT-SLAM parameters (config/params_ltslam.yaml).",
                               [](const slam::SlamConfig& c, const std::string& w) { ValidateConfig(c, w); });
  BindConfig<removert::RemovertConfig>(
      m, "RemovertConfig", "LT-removert parameters (config/params_ltremovert.yaml).",
      [](const removert::RemovertConfig& c, const std::string& w) { c.Validate(w); });
  BindConfig<map::MapConfig>(m, "MapConfig", "LT-map parameters (config/params_ltmap.yaml).",
                             [](const map::MapConfig& c, const std::string& w) { ValidateConfig(c, w); });
  BindConfig<eval::EvalConfig>(m, "EvalConfig", "Evaluation parameters (config/params_eval.yaml).",
                               [](const eval::EvalConfig& c, const std::string& w) { c.Validate(w); });
  BindConfig<pipeline::RunConfig>(m, "RunConfig", "`ltmapper run` parameters (config/params_run.yaml).",
                                  [](const pipeline::RunConfig& c, const std::string& w) { ValidateConfig(c, w); });

  // ----------------------------------------------------------------------------------- sim
  m.def(
      "simulate",
      [](const sim::SimConfig& cfg, const std::string& out, int threads) {
        sim::CheckConfig(cfg, "sim config");
        sim::SimReport r;
        {
          py::gil_scoped_release unlock;
          r = sim::Simulate(cfg, out, threads);
        }
        return SimReportToDict(r);
      },
      py::arg("cfg"), py::arg("out"), py::arg("threads") = 0,
      "`ltmapper sim`: writes OUT/sessions/session_XX and OUT/truth (docs/FORMATS.md).");

  // --------------------------------------------------------------------------------- LT-SLAM
  m.def(
      "run_slam",
      [](const slam::SlamConfig& cfg, const std::string& central, const py::object& queries, const std::string& out,
         int threads) {
        ValidateConfig(cfg, "slam config");
        std::vector<std::string> dirs = {central};
        for (const auto& q : Strings(queries)) dirs.push_back(q);
        if (dirs.size() < 2) throw Error("LT-SLAM needs a central session and at least one query");
        slam::SlamResult r;
        {
          py::gil_scoped_release unlock;
          r = slam::RunSlamStage(cfg, dirs, out, threads);
        }
        return SlamToDict(r);
      },
      py::arg("cfg"), py::arg("central"), py::arg("queries"), py::arg("out"), py::arg("threads") = 0,
      "`ltmapper slam`: aligns the query session directories to the central one; writes OUT (aligned/).");

  // ------------------------------------------------------------------------------ LT-removert
  m.def(
      "run_removert",
      [](const removert::RemovertConfig& cfg, const py::object& sessions, const py::object& poses_files,
         const std::string& out, int threads) {
        cfg.Validate("removert config");
        const std::vector<std::string> dirs = Strings(sessions);
        std::vector<std::string> poses;
        if (py::isinstance<py::str>(poses_files)) {
          // An LT-SLAM output dir: <aligned>/<session name>/poses_world.txt, as `removert --aligned`.
          const std::string aligned = py::cast<std::string>(poses_files);
          for (const auto& s : dirs) {
            const std::string name = std::filesystem::path(s).lexically_normal().filename().string();
            poses.push_back(aligned + "/" +
                            (name.empty() ? std::filesystem::path(s).parent_path().filename().string() : name) +
                            "/poses_world.txt");
          }
        } else {
          poses = Strings(poses_files);
        }
        if (poses.size() != dirs.size())
          throw Error("need one pose file per session: " + std::to_string(dirs.size()) + " sessions, " +
                      std::to_string(poses.size()) + " pose files");
        removert::StageReport r;
        {
          py::gil_scoped_release unlock;
          r = removert::RunRemovertStage(cfg, dirs, poses, out, threads);
        }
        return StageReportToDict(r);
      },
      py::arg("cfg"), py::arg("sessions"), py::arg("poses_files"), py::arg("out"), py::arg("threads") = 0,
      "`ltmapper removert`: session dirs (first = central) + one KITTI world-pose file per session (or an LT-SLAM "
      "aligned/ dir as a string); writes OUT (changes/).");
  m.def(
      "remove_hd",
      [](const removert::RemovertConfig& cfg, const Session& session, const py::object& poses, int threads) {
        cfg.Validate("removert config");
        const auto kfs = WorldKeyframes(session, poses);
        removert::HdResult r;
        {
          py::gil_scoped_release unlock;
          r = removert::RemoveHd(kfs, cfg, threads);
        }
        py::dict d;
        d["static_map"] = PointsToNumpy(r.static_map);
        d["hd_map"] = PointsToNumpy(r.hd_map);
        d["stats"] = HdStatsToDict(r.stats);
        return d;
      },
      py::arg("cfg"), py::arg("session"), py::arg("poses") = py::none(), py::arg("threads") = 0,
      "HD removal of one loaded session (removert::RemoveHd): poses = world poses (N,4,4), default the session's "
      "own. Returns {static_map, hd_map: (N,4) float32, stats: dict}.");
  m.def(
      "build_session_map",
      [](const removert::RemovertConfig& cfg, const Session& session, const py::object& poses, int threads) {
        cfg.Validate("removert config");
        const auto kfs = WorldKeyframes(session, poses);
        PointCloud map;
        {
          py::gil_scoped_release unlock;
          map = removert::BuildSessionMap(kfs, removert::WithSensor(cfg, kfs), threads);
        }
        return PointsToNumpy(map);
      },
      py::arg("cfg"), py::arg("session"), py::arg("poses") = py::none(), py::arg("threads") = 0,
      "The session map LT-removert works on (union of the scans in the world, range-filtered, voxelised).");
  m.def(
      "resolve_removert_sensor",
      [](const removert::RemovertConfig& cfg, const Session& session) {
        const auto kfs = WorldKeyframes(session, py::none());
        py::gil_scoped_release unlock;
        return removert::WithSensor(cfg, kfs).sensor_model;
      },
      py::arg("cfg"), py::arg("session"), "The sensor model LT-removert uses for this session (sensor.model).");

  // -------------------------------------------------------------------------------- LT-map
  m.def(
      "aligned_sessions",
      [](const std::string& aligned, const std::string& central) {
        map::PipelineDirs dirs;
        dirs.aligned = aligned;
        return map::AlignedSessions(dirs, central);
      },
      py::arg("aligned"), py::arg("central") = "", "Session names in an LT-SLAM output dir (central first when given).");
  m.def(
      "map_init",
      [](const std::string& store, const map::MapConfig& cfg, const std::string& aligned, const std::string& changes,
         const std::string& sessions_root, const std::string& central, int threads) {
        ValidateConfig(cfg, "map config");
        map::PipelineDirs dirs{aligned, changes, sessions_root};
        map::IntegrationResult r;
        {
          py::gil_scoped_release unlock;
          r = map::InitFromDirs(store, cfg, dirs, central, threads);
        }
        return IntegrationToDict(r);
      },
      py::arg("store"), py::arg("cfg"), py::arg("aligned"), py::arg("changes"), py::arg("sessions_root") = "",
      py::arg("central") = "", py::arg("threads") = 0,
      "`ltmapper map init`: creates STORE with the central session as base.");
  m.def(
      "map_integrate",
      [](const std::string& store_path, const map::MapConfig& cfg, const std::string& aligned,
         const std::string& changes, const py::object& sessions, const std::string& sessions_root,
         const std::string& central, int threads) {
        ValidateConfig(cfg, "map config");
        map::PipelineDirs dirs{aligned, changes, sessions_root};
        std::vector<std::string> todo;
        if (!sessions.is_none()) todo = Strings(sessions);
        py::list results;
        std::vector<std::pair<std::string, map::IntegrationResult>> done;
        {
          py::gil_scoped_release unlock;
          if (!std::filesystem::exists(store_path))
            done.emplace_back("central", map::InitFromDirs(store_path, cfg, dirs, central, threads));
          map::Store store = map::Store::Open(store_path, cfg, map::Store::Access::kReadWrite);
          store.set_threads(threads);
          if (todo.empty()) {
            std::vector<std::string> have;
            for (const auto& s : store.Sessions()) have.push_back(s.name);
            for (const auto& n : map::AlignedSessions(dirs, store.Sessions().at(0).name))
              if (std::find(have.begin(), have.end(), n) == have.end()) todo.push_back(n);
          }
          for (const auto& name : todo) done.emplace_back(name, map::IntegrateFromDirs(store, dirs, name));
        }
        for (const auto& [name, r] : done) {
          py::dict d = IntegrationToDict(r);
          d["name"] = name;
          results.append(d);
        }
        return results;
      },
      py::arg("store"), py::arg("cfg"), py::arg("aligned"), py::arg("changes"), py::arg("sessions") = py::none(),
      py::arg("sessions_root") = "", py::arg("central") = "", py::arg("threads") = 0,
      "`ltmapper map integrate`: integrates query sessions (default: every one not yet in the store; creates the "
      "store when missing). Returns one dict per integration step.");

  // ------------------------------------------------------------------------------ pipeline
  m.def(
      "run_pipeline",
      [](const pipeline::RunConfig& cfg, const py::object& sessions, const std::string& out, int threads) {
        ValidateConfig(cfg, "run config");
        const std::vector<std::string> dirs = Strings(sessions);
        pipeline::RunReport r;
        {
          py::gil_scoped_release unlock;
          r = pipeline::RunPipeline(cfg, dirs, out, threads);
        }
        return RunReportToDict(r);
      },
      py::arg("cfg"), py::arg("sessions"), py::arg("out"), py::arg("threads") = 0,
      "`ltmapper run`: LT-SLAM -> LT-removert -> LT-map into OUT (resumes finished stages).");
}

}  // namespace ltm::py_bind
