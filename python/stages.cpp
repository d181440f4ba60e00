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
    PutFields(d, s, LTM_KV(s, name), LTM_KV(s, aligned), LTM_KV(s, reason));
    d["anchor"] = PoseToNumpy(s.anchor);
    d["T_session_sensor"] = PosesToNumpy(s.T_session_sensor);
    d["T_world_sensor"] = PosesToNumpy(s.T_world_sensor);
    PutFields(d, s, LTM_KV(s, sc_candidates), LTM_KV(s, loops_verified), LTM_KV(s, loops_accepted),
              LTM_KV(s, radius_loops), LTM_KV(s, own_loops));
    sessions.append(d);
  }
  py::list loops;
  for (const auto& l : r.loops) {
    py::dict d;
    d["a"] = py::make_tuple(l.a.session, l.a.keyframe);
    d["b"] = py::make_tuple(l.b.session, l.b.keyframe);
    PutFields(d, l, LTM_KV(l, source), LTM_KV(l, sc_distance), LTM_KV(l, yaw_deg));
    d["T_a_b"] = PoseToNumpy(l.T_a_b);
    PutFields(d, l, LTM_KV(l, fitness), LTM_KV(l, verified), LTM_KV(l, accepted), LTM_KV(l, status),
              LTM_KV(l, residual_t_m), LTM_KV(l, residual_r_deg));
    loops.append(d);
  }
  py::dict d;
  d["sessions"] = sessions;
  d["loops"] = loops;
  PutFields(d, r, LTM_KV(r, time_descriptors_s), LTM_KV(r, time_retrieval_s), LTM_KV(r, time_registration_s),
            LTM_KV(r, time_optimisation_s), LTM_KV(r, time_total_s), LTM_KV(r, registrations), LTM_KV(r, refine_radius_m), LTM_KV(r, max_translation_m),
            LTM_KV(r, solution_usable), LTM_KV(r, initial_cost), LTM_KV(r, final_cost), LTM_KV(r, solver_iterations));
  return d;
}

py::dict HdStatsToDict(const removert::HdStats& h) {
  py::dict d;
  PutFields(d, h, LTM_KV(h, map_points), LTM_KV(h, removed_per_resolution), LTM_KV(h, candidates),
            LTM_KV(h, reverted), LTM_KV(h, removed), LTM_KV(h, dilated), LTM_KV(h, seconds_map),
            LTM_KV(h, seconds_votes));
  return d;
}

py::dict LdStatsToDict(const removert::LdStats& l) {
  py::dict d;
  PutFields(d, l, LTM_KV(l, central_points), LTM_KV(l, query_points), LTM_KV(l, nd_strong), LTM_KV(l, nd_weak),
            LTM_KV(l, pd_strong), LTM_KV(l, pd_weak), LTM_KV(l, pd_unobserved), LTM_KV(l, nd_unobserved),
            LTM_KV(l, pd_same), LTM_KV(l, nd_same), LTM_KV(l, nd_residue), LTM_KV(l, pd_residue),
            LTM_KV(l, seconds));
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
  PutFields(d, r, LTM_KV(r, new_keyframes), LTM_KV(r, seconds), LTM_KV(r, peak_rss_bytes));
  return d;
}

py::dict SimReportToDict(const sim::SimReport& r) {
  py::list pairs;
  for (const auto& p : r.pairs) {
    py::dict d;
    PutFields(d, p, LTM_KV(p, query), LTM_KV(p, pd_strong), LTM_KV(p, pd_weak), LTM_KV(p, nd_strong),
              LTM_KV(p, nd_weak), LTM_KV(p, objects_pd_strong), LTM_KV(p, objects_pd_weak),
              LTM_KV(p, objects_nd_strong), LTM_KV(p, objects_nd_weak), LTM_KV(p, rays));
    pairs.append(d);
  }
  py::dict d;
  PutFields(d, r, LTM_KV(r, sessions), LTM_KV(r, keyframes), LTM_KV(r, triangles), LTM_KV(r, ld_objects),
            LTM_KV(r, hd_actors), LTM_KV(r, rays), LTM_KV(r, points), LTM_KV(r, hd_points), LTM_KV(r, ld_points),
            LTM_KV(r, rays_per_s), LTM_KV(r, seconds_build), LTM_KV(r, seconds_cast), LTM_KV(r, seconds_write),
            LTM_KV(r, seconds_truth), LTM_KV(r, seconds_total), LTM_KV(r, bytes_written));
  d["pairs"] = pairs;
  return d;
}

py::dict RunReportToDict(const pipeline::RunReport& r) {
  py::list stages;
  for (const auto& s : r.stages) {
    py::dict d;
    PutFields(d, s, LTM_KV(s, stage), LTM_KV(s, skipped), LTM_KV(s, seconds));
    stages.append(d);
  }
  py::dict d;
  PutFields(d, r, LTM_KV(r, sessions), LTM_KV(r, aligned), LTM_KV(r, not_aligned));
  d["stages"] = stages;
  PutFields(d, r, LTM_KV(r, map_points_live), LTM_KV(r, map_points_meta), LTM_KV(r, objects), LTM_KV(r, store_bytes),
            LTM_KV(r, seconds), LTM_KV(r, peak_rss_bytes));
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
    w.sweep = s.keyframes[i].sweep;
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

// The stages' config classes: read, write, validate.
void BindConfigs(py::module_& m) {
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
}

// The simulator.
void BindSim(py::module_& m) {
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
}

// LT-SLAM.
void BindSlam(py::module_& m) {
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
}

// LT-removert: HD removal and LD changes.
void BindRemovert(py::module_& m) {
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
}

// LT-map: the store.
void BindMap(py::module_& m) {
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
}

// `ltmapper run`.
void BindPipeline(py::module_& m) {
  m.def(
      "run_pipeline",
      [](const pipeline::RunConfig& cfg, const py::object& sessions, const std::string& out, int threads,
         const py::object& poses) {
        ValidateConfig(cfg, "run config");
        const std::vector<std::string> dirs = Strings(sessions);
        const std::vector<std::string> pose_files = poses.is_none() ? std::vector<std::string>() : Strings(poses);
        pipeline::RunReport r;
        {
          py::gil_scoped_release unlock;
          r = pipeline::RunPipeline(cfg, dirs, out, threads, pose_files);
        }
        return RunReportToDict(r);
      },
      py::arg("cfg"), py::arg("sessions"), py::arg("out"), py::arg("threads") = 0, py::arg("poses") = py::none(),
      "`ltmapper run`: LT-SLAM -> LT-removert -> LT-map into OUT (resumes finished stages). poses: one KITTI "
      "world-pose file per session (`run --poses`): the sessions placed by them, their rotation error measured.");
}

}  // namespace

void BindStages(py::module_& m) {
  BindConfigs(m);
  BindSim(m);
  BindSlam(m);
  BindRemovert(m);
  BindMap(m);
  BindPipeline(m);
}

}  // namespace ltm::py_bind
