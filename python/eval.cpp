// Evaluators of ltm::eval (trajectories ATE / RPE / consistency, HD removal SA / DA / AA) as
// functions returning the report's JSON section as a plain dict (NaN ratios are None).
#include "convert.hpp"

#include "ltmapper/eval/eval.hpp"

#include <map>
#include <optional>
#include <utility>

namespace ltm::py_bind {
namespace {

py::object Section(const eval::Report& r, const char* key) { return JsonLoads(eval::ToJson(r))[key]; }

eval::SessionTrajectory TrajectoryFromPython(const py::handle& obj, std::size_t i) {
  eval::SessionTrajectory t;
  const std::string what = "session " + std::to_string(i);
  if (py::isinstance<py::dict>(obj)) {
    const py::dict d = py::reinterpret_borrow<py::dict>(obj);
    t.name = d.contains("name") ? py::cast<std::string>(d["name"]) : "session_" + std::to_string(i);
    if (!d.contains("truth") || !d.contains("est")) throw py::value_error(what + ": needs \"truth\" and \"est\" poses");
    t.truth = PosesFromPython(d["truth"], what + " truth");
    t.est = PosesFromPython(d["est"], what + " est");
  } else {
    const py::tuple tp = py::cast<py::tuple>(obj);
    if (tp.size() != 3) throw py::value_error(what + ": expected (name, truth, est)");
    t.name = py::cast<std::string>(tp[0]);
    t.truth = PosesFromPython(tp[1], what + " truth");
    t.est = PosesFromPython(tp[2], what + " est");
  }
  return t;
}

py::list TrajectoriesToList(const std::vector<eval::SessionTrajectory>& sessions) {
  py::list out;
  for (const auto& s : sessions) {
    py::dict d;
    d["name"] = s.name;
    d["truth"] = PosesToNumpy(s.truth);
    d["est"] = PosesToNumpy(s.est);
    out.append(d);
  }
  return out;
}

eval::ChangeClouds ChangesFromPython(const py::object& obj, const std::string& what) {
  const py::dict d = py::cast<py::dict>(obj);
  eval::ChangeClouds c;
  const std::pair<const char*, PointCloud*> parts[] = {
      {"pd_strong", &c.pd_strong}, {"pd_weak", &c.pd_weak}, {"nd_strong", &c.nd_strong}, {"nd_weak", &c.nd_weak}};
  for (const auto& [key, cloud] : parts) {
    if (!d.contains(key)) throw py::value_error(what + ": missing \"" + std::string(key) + "\"");
    *cloud = CloudFromPython(d[key], what + "[\"" + key + "\"]");
  }
  return c;
}

py::dict ChangesToDict(const eval::ChangeClouds& c) {
  py::dict d;
  d["pd_strong"] = PointsToNumpy(c.pd_strong);
  d["pd_weak"] = PointsToNumpy(c.pd_weak);
  d["nd_strong"] = PointsToNumpy(c.nd_strong);
  d["nd_weak"] = PointsToNumpy(c.nd_weak);
  return d;
}

std::map<int, std::string> ObjectClasses(const py::object& obj) {
  if (obj.is_none()) return {};
  if (py::isinstance<py::str>(obj)) return eval::ReadObjectClasses(py::cast<std::string>(obj));
  return py::cast<std::map<int, std::string>>(obj);
}

}  // namespace

void BindEval(py::module_& m) {
  m.def(
      "evaluate_trajectories",
      [](const py::iterable& sessions, const py::object& cfg_obj) {
        const eval::EvalConfig cfg = cfg_obj.is_none() ? eval::EvalConfig{} : py::cast<eval::EvalConfig>(cfg_obj);
        cfg.Validate("eval config");
        std::vector<eval::SessionTrajectory> trajs;
        for (auto s : sessions) trajs.push_back(TrajectoryFromPython(s, trajs.size()));
        eval::Report r;
        {
          py::gil_scoped_release unlock;
          r.traj = eval::EvaluateTrajectories(trajs, cfg);
        }
        return Section(r, "traj");
      },
      py::arg("sessions"), py::arg("cfg") = py::none(),
      "ATE / RPE / inter-session consistency (`ltmapper eval traj`). sessions: list of {name, truth (N,4,4), est "
      "(N,4,4)} dicts or (name, truth, est) tuples, central first. Returns the report's \"traj\" dict.");
  m.def(
      "load_sim_trajectories",
      [](const std::string& sim_dir, const std::string& est_dir) {
        std::vector<std::string> missing;
        const auto s = eval::LoadSimTrajectories(sim_dir, est_dir, &missing);
        py::dict d;
        d["sessions"] = TrajectoriesToList(s);
        d["missing"] = missing;
        return d;
      },
      py::arg("sim_dir"), py::arg("est_dir") = "",
      "True and estimated poses of a sim dir: estimates from EST_DIR/<s>/poses_world.txt (LT-SLAM aligned/), or the "
      "drifted session odometry when est_dir is empty. Returns {sessions: [...], missing: [names]}.");
  m.def(
      "evaluate_hd",
      [](const py::object& truth, const py::object& output, const py::object& cfg_obj, const py::object& object_classes,
         int threads) {
        const eval::EvalConfig cfg = cfg_obj.is_none() ? eval::EvalConfig{} : py::cast<eval::EvalConfig>(cfg_obj);
        cfg.Validate("eval config");
        std::vector<PointCloud> pieces;
        if (py::isinstance<py::list>(truth) || py::isinstance<py::tuple>(truth)) {
          for (auto t : py::reinterpret_borrow<py::iterable>(truth))
            pieces.push_back(CloudFromPython(t, "truth " + std::to_string(pieces.size())));
        } else {
          pieces.push_back(CloudFromPython(truth, "truth"));
        }
        PointCloud out = CloudFromPython(output, "output");
        const auto classes = ObjectClasses(object_classes);
        eval::Report r;
        {
          py::gil_scoped_release unlock;
          eval::HdEvaluator ev(std::move(out), cfg, classes, threads);
          for (const auto& p : pieces) ev.Add(p);
          r.hd = ev.Result();
        }
        return Section(r, "hd");
      },
      py::arg("truth"), py::arg("output"), py::arg("cfg") = py::none(), py::arg("object_classes") = py::none(),
      py::arg("threads") = 0,
      "Point-wise SA / DA / AA of an HD-free map (`ltmapper eval hd`). truth: a labelled cloud dict (cls required, "
      "object optional) or a list of them, same frame as output ((N,3|4) array). object_classes: {id: class} or a "
      "truth/objects.csv path. Returns the report's \"hd\" dict.");
  m.def(
      "evaluate_hd_sim",
      [](const std::string& sim_dir, const std::string& session, const py::object& output, const py::object& poses,
         const py::object& cfg_obj, const py::object& object_classes, int threads) {
        const eval::EvalConfig cfg = cfg_obj.is_none() ? eval::EvalConfig{} : py::cast<eval::EvalConfig>(cfg_obj);
        cfg.Validate("eval config");
        PointCloud out = CloudFromPython(output, "output");
        const std::vector<Pose> T = PosesFromPython(poses, "poses");
        const auto classes = ObjectClasses(object_classes);
        eval::Report r;
        std::size_t used = 0;
        {
          py::gil_scoped_release unlock;
          eval::HdEvaluator ev(std::move(out), cfg, classes, threads);
          used = eval::AddSimSessionTruth(ev, sim_dir, session, T, cfg);
          r.hd = ev.Result();
        }
        py::dict d = py::cast<py::dict>(Section(r, "hd"));
        d["scans"] = used;
        return d;
      },
      py::arg("sim_dir"), py::arg("session"), py::arg("output"), py::arg("poses"), py::arg("cfg") = py::none(),
      py::arg("object_classes") = py::none(), py::arg("threads") = 0,
      "`ltmapper eval hd --sim`: the session's labelled scans (truth/<session>/labels) placed with poses (N,4,4, "
      "the output's frame) scored against the output map. Returns the \"hd\" dict plus \"scans\".");
  m.def(
      "truth_to_estimate_frame",
      [](const std::string& sim_dir, const std::string& aligned_dir) {
        return PoseToNumpy(eval::TruthToEstimateFrame(sim_dir, aligned_dir));
      },
      py::arg("sim_dir"), py::arg("aligned_dir") = "",
      "(4,4) transform from the sim's true world into the estimated world (joint ATE alignment with aligned_dir, "
      "else the inverse of the central session's true origin).");
  m.def(
      "read_poses", [](const std::string& path) { return PosesToNumpy(eval::ReadPoses(path)); }, py::arg("path"),
      "KITTI (12 numbers) or TUM (8) pose file as (N,4,4).");
  m.def(
      "read_change_clouds", [](const std::string& dir) { return ChangesToDict(eval::ReadChangeClouds(dir)); },
      py::arg("dir"), "The four change clouds {pd_strong, pd_weak, nd_strong, nd_weak}.pcd of a pair folder.");
  m.def(
      "read_object_change_clouds",
      [](const std::string& dir) -> py::object {
        const auto c = eval::ReadObjectChangeClouds(dir);
        return c ? py::object(ChangesToDict(*c)) : py::object(py::none());
      },
      py::arg("dir"),
      "The truth's points of changed objects (objects_{pd,nd}_{strong,weak}.pcd of a sim pair folder) as "
      "read_change_clouds returns them; None when any of the four is missing.");
  m.def("find_pair_dir", &eval::FindPairDir, py::arg("root"), py::arg("pair"),
        "ROOT/pair_<pair> (\"00_01\" also finds pair_session_00_session_01 ...).");
  m.def(
      "cleaned_session_map",
      [](const std::string& changes, const std::string& session, const py::object& cfg_obj, int threads) {
        const eval::EvalConfig cfg = cfg_obj.is_none() ? eval::EvalConfig{} : py::cast<eval::EvalConfig>(cfg_obj);
        std::string note;
        PointCloud c;
        {
          py::gil_scoped_release unlock;
          c = eval::CleanedSessionMap(changes, session, cfg, threads, &note);
        }
        return py::make_tuple(PointsToNumpy(c), note);
      },
      py::arg("changes"), py::arg("session"), py::arg("cfg") = py::none(), py::arg("threads") = 0,
      "A session's HD-free map after LT-removert's multi-session cleanup (what `eval hd --changes` scores): "
      "(points (N,4), what was taken out).");
  m.def(
      "kept_map_from_changes",
      [](const py::object& central_static, const py::object& nd_strong, const py::object& cfg_obj, int threads) {
        const eval::EvalConfig cfg = cfg_obj.is_none() ? eval::EvalConfig{} : py::cast<eval::EvalConfig>(cfg_obj);
        const PointCloud a = CloudFromPython(central_static, "central_static"), b = CloudFromPython(nd_strong, "nd_strong");
        PointCloud k;
        {
          py::gil_scoped_release unlock;
          k = eval::KeptMapFromChanges(a, b, cfg, threads);
        }
        return PointsToNumpy(k);
      },
      py::arg("central_static"), py::arg("nd_strong"), py::arg("cfg") = py::none(), py::arg("threads") = 0,
      "The central static map minus the points with a predicted strong-ND point within ld.same_point_m.");
  m.def(
      "evaluate_ld",
      [](const py::object& truth, const py::object& predicted, const py::object& kept_map, const py::object& cfg_obj,
         const py::object& trajectories, const py::object& truth_objects, int threads) {
        const eval::EvalConfig cfg = cfg_obj.is_none() ? eval::EvalConfig{} : py::cast<eval::EvalConfig>(cfg_obj);
        cfg.Validate("eval config");
        const eval::ChangeClouds t = ChangesFromPython(truth, "truth"), p = ChangesFromPython(predicted, "predicted");
        std::optional<PointCloud> kept;
        if (!kept_map.is_none()) kept = CloudFromPython(kept_map, "kept_map");
        std::optional<eval::LdTrajectories> traj;
        if (!trajectories.is_none()) {
          const py::tuple tp = py::cast<py::tuple>(trajectories);
          if (tp.size() != 2) throw py::value_error("trajectories: (central positions, query positions)");
          traj = eval::LdTrajectories{CloudFromPython(tp[0], "central positions"), CloudFromPython(tp[1], "query positions")};
        }
        std::optional<eval::ChangeClouds> objects;
        if (!truth_objects.is_none()) objects = ChangesFromPython(truth_objects, "truth_objects");
        eval::Report r;
        {
          py::gil_scoped_release unlock;
          r.ld = eval::EvaluateLd(t, p, kept ? &*kept : nullptr, cfg, threads, traj ? &*traj : nullptr,
                                  objects ? &*objects : nullptr);
        }
        return Section(r, "ld");
      },
      py::arg("truth"), py::arg("predicted"), py::arg("kept_map") = py::none(), py::arg("cfg") = py::none(),
      py::arg("trajectories") = py::none(), py::arg("truth_objects") = py::none(), py::arg("threads") = 0,
      "P / R / F1 of PD and ND (`ltmapper eval ld`). truth / predicted: dicts of the four change clouds (as "
      "read_change_clouds returns), same frame; kept_map: the map kept after the update (weak-ND check); "
      "trajectories: (central, query) keyframe positions (N,3) for the distance bands; truth_objects: the "
      "truth's points of changed objects (read_object_change_clouds), for pd_objects / nd_objects. Returns the "
      "\"ld\" dict.");
  m.def("sim_session_names", &eval::SimSessionNames, py::arg("sim_dir"));
  m.def("read_object_classes", &eval::ReadObjectClasses, py::arg("objects_csv"));
}

}  // namespace ltm::py_bind
