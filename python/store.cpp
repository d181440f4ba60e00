// ltmapper.Store: the LT-map store (map::Store) with clouds as NumPy dicts and records as dicts.
#include "convert.hpp"

#include "ltmapper/map/map.hpp"

namespace ltm::py_bind {

py::dict IntegrationToDict(const map::IntegrationResult& r) {
  py::dict d;
  PutFields(d, r, LTM_KV(r, session), LTM_KV(r, keyframes_new), LTM_KV(r, keyframes_changed), LTM_KV(r, pd_strong),
            LTM_KV(r, pd_weak), LTM_KV(r, nd_strong), LTM_KV(r, nd_weak), LTM_KV(r, superseded), LTM_KV(r, restored),
            LTM_KV(r, points), LTM_KV(r, bytes), LTM_KV(r, seconds));
  return d;
}

namespace {

py::array_t<double> Vec3(const Eigen::Vector3d& v) {
  py::array_t<double> a(3);
  for (int i = 0; i < 3; ++i) a.mutable_at(i) = v[i];
  return a;
}

py::dict SessionToDict(const map::SessionRecord& s) {
  py::dict d;
  PutFields(d, s, LTM_KV(s, order), LTM_KV(s, name), LTM_KV(s, reference));
  d["anchor"] = PoseToNumpy(s.anchor);
  PutFields(d, s, LTM_KV(s, params), LTM_KV(s, integrated_utc), LTM_KV(s, keyframes_new),
            LTM_KV(s, keyframes_changed), LTM_KV(s, pd_strong), LTM_KV(s, pd_weak), LTM_KV(s, nd_strong),
            LTM_KV(s, nd_weak), LTM_KV(s, superseded), LTM_KV(s, restored), LTM_KV(s, points), LTM_KV(s, bytes));
  return d;
}

py::dict KeyframeToDict(const map::KeyframeRecord& k) {
  py::dict d;
  PutFields(d, k, LTM_KV(k, id), LTM_KV(k, session), LTM_KV(k, source_index));
  d["T_world_sensor"] = PoseToNumpy(k.T_world_sensor);
  PutFields(d, k, LTM_KV(k, base_points), LTM_KV(k, base_bytes), LTM_KV(k, delta_count), LTM_KV(k, delta_bytes));
  return d;
}

py::dict ObjectToDict(const map::MapObject& o) {
  py::dict d;
  PutFields(d, o, LTM_KV(o, id), LTM_KV(o, session), LTM_KV(o, reference));
  d["cls"] = std::string(ToString(o.cls));
  d["points"] = o.points;
  d["centroid"] = Vec3(o.centroid);
  d["lo"] = Vec3(o.lo);
  d["hi"] = Vec3(o.hi);
  PutFields(d, o, LTM_KV(o, change), LTM_KV(o, partner), LTM_KV(o, move_candidates), LTM_KV(o, alike_beside),
            LTM_KV(o, hidden_length_m), LTM_KV(o, exists_in), LTM_KV(o, confidence));
  PutFields(d, o, LTM_KV(o, track), LTM_KV(o, track_sessions));
  d["box_center"] = Vec3(o.box_center);
  d["size"] = Vec3(o.size);
  d["yaw_rad"] = o.yaw_rad;
  d["height_above_ground"] = o.height_above_ground;
  d["cloud"] = CloudToDict(o.cloud);
  return d;
}

// Session given as an order number or a name.
int SessionArg(const map::Store& s, const py::object& session) {
  if (py::isinstance<py::str>(session)) return s.SessionOrder(py::cast<std::string>(session));
  const int k = py::cast<int>(session);
  if (k < 0 || k > s.LatestSession())
    throw Error(s.path() + ": no session " + std::to_string(k) + " (0.." + std::to_string(s.LatestSession()) + ")");
  return k;
}

// box = ((x, y, z), (x, y, z)) or None; voxel None = the store config's output_voxel_m.
map::Region RegionArg(const map::Store& s, const py::object& box, const py::object& voxel) {
  map::Region r;
  r.voxel_m = voxel.is_none() ? s.config().output_voxel_m : py::cast<double>(voxel);
  if (r.voxel_m < 0) throw py::value_error("voxel must be >= 0");
  if (!box.is_none()) {
    const auto b = py::cast<std::vector<std::vector<double>>>(box);
    if (b.size() != 2 || b[0].size() != 3 || b[1].size() != 3)
      throw py::value_error("box must be ((xmin, ymin, zmin), (xmax, ymax, zmax))");
    r.use_box = true;
    r.lo = Eigen::Vector3d(b[0][0], b[0][1], b[0][2]);
    r.hi = Eigen::Vector3d(b[1][0], b[1][1], b[1][2]);
    if ((r.lo.array() > r.hi.array()).any()) throw py::value_error("box: min must not exceed max");
  }
  return r;
}

template <class F>
py::dict Cloud(F&& f) {
  PointCloud c;
  {
    py::gil_scoped_release unlock;
    c = f();
  }
  return CloudToDict(c);
}

}  // namespace

void BindStore(py::module_& m) {
  using map::Store;
  py::class_<Store>(m, "Store",
                    "An LT-map store (NAME.ltmap). Clouds come back as dicts {points (N,4) float32, cls uint8, "
                    "session uint16[, object int32]} in the world frame; class codes index ltmapper.CLASS_NAMES.")
      .def(py::init([](const std::string& path, const py::object& cfg, bool read_only, int threads) {
             const map::MapConfig c = cfg.is_none() ? map::MapConfig{} : py::cast<map::MapConfig>(cfg);
             Store s = Store::Open(path, c, read_only ? Store::Access::kReadOnly : Store::Access::kReadWrite);
             s.set_threads(threads);
             return s;
           }),
           py::arg("path"), py::arg("cfg") = py::none(), py::arg("read_only") = true, py::arg("threads") = 0,
           "Opens an existing store (read-only by default: nothing is written, no -wal / -shm left behind).")
      .def_property_readonly("path", &Store::path)
      .def_property_readonly("config", [](const Store& s) { return s.config(); },
                             "The MapConfig in use (encoding fields as stored).")
      .def("set_threads", &Store::set_threads, py::arg("threads"))
      .def("sessions",
           [](const Store& s) {
             py::list out;
             for (const auto& r : s.Sessions()) out.append(SessionToDict(r));
             return out;
           })
      .def("session_names",
           [](const Store& s) {
             std::vector<std::string> out;
             for (const auto& r : s.Sessions()) out.push_back(r.name);
             return out;
           })
      .def("keyframes",
           [](const Store& s) {
             py::list out;
             for (const auto& k : s.Keyframes()) out.append(KeyframeToDict(k));
             return out;
           })
      .def("session_order", &Store::SessionOrder, py::arg("name"))
      .def_property_readonly("latest_session", &Store::LatestSession)
      .def("totals",
           [](const Store& s) {
             const auto t = s.Totals();
             py::dict d;
             PutFields(d, t, LTM_KV(t, file_bytes), LTM_KV(t, base_bytes), LTM_KV(t, delta_bytes),
                       LTM_KV(t, base_points), LTM_KV(t, delta_points));
             return d;
           })
      .def(
          "keyframe_cloud",
          [](const Store& s, int id, const py::object& session) {
            const int k = SessionArg(s, session);
            return Cloud([&] { return s.KeyframeCloud(id, k); });
          },
          py::arg("keyframe_id"), py::arg("session"), "One keyframe as of a session, in its local frame.")
      .def(
          "map_at",
          [](const Store& s, const py::object& session, const py::object& box, const py::object& voxel) {
            const int k = SessionArg(s, session);
            const map::Region r = RegionArg(s, box, voxel);
            return Cloud([&] { return s.MapAt(k, r); });
          },
          py::arg("session"), py::arg("box") = py::none(), py::arg("voxel") = py::none(),
          "The map as it was at a session (order or name), by chained inverse deltas (`map restore`).")
      .def(
          "live",
          [](const Store& s, const py::object& box, const py::object& voxel) {
            const map::Region r = RegionArg(s, box, voxel);
            return Cloud([&] { return s.Live(r); });
          },
          py::arg("box") = py::none(), py::arg("voxel") = py::none(), "The live map (latest state).")
      .def(
          "meta",
          [](const Store& s, const py::object& box, const py::object& voxel) {
            const map::Region r = RegionArg(s, box, voxel);
            return Cloud([&] { return s.Meta(r); });
          },
          py::arg("box") = py::none(), py::arg("voxel") = py::none(),
          "The meta map (first states plus strong PD, seen-through space carved).")
      .def(
          "step_changes",
          [](const Store& s, const py::object& session, const py::object& box, const py::object& voxel) {
            const int k = SessionArg(s, session);
            const map::Region r = RegionArg(s, box, voxel);
            return Cloud([&] { return s.StepChanges(k, r); });
          },
          py::arg("session"), py::arg("box") = py::none(), py::arg("voxel") = py::none(),
          "The PD / ND changes one step applied (world frame).")
      .def(
          "objects",
          [](const Store& s) {
            std::vector<map::MapObject> objs;
            {
              py::gil_scoped_release unlock;
              objs = s.Objects();
            }
            py::list out;
            for (const auto& o : objs) out.append(ObjectToDict(o));
            return out;
          },
          "Changed objects a user can act on (clusters of strong ND / PD per step in observed space that "
          "pass the geometric rules; change appeared / disappeared / moved, oriented box) as dicts with their clouds.")
      .def(
          "write_objects",
          [](const Store& s, const std::string& dir) {
            py::gil_scoped_release unlock;
            map::WriteObjects(dir, s.Objects());
          },
          py::arg("dir"), "`ltmapper map objects`: objects.csv / .json / .ply and clouds/ into DIR.")
      .def(
          "integrate",
          [](Store& s, const std::string& aligned, const std::string& changes, const std::string& session,
             const std::string& sessions_root) {
            map::PipelineDirs dirs{aligned, changes, sessions_root};
            map::IntegrationResult r;
            {
              py::gil_scoped_release unlock;
              r = map::IntegrateFromDirs(s, dirs, session);
            }
            return IntegrationToDict(r);
          },
          py::arg("aligned"), py::arg("changes"), py::arg("session"), py::arg("sessions_root") = "",
          "Integrates one query session from the LT-SLAM / LT-removert output dirs (store opened read_only=False).")
      .def("fsck",
           [](const Store& s) {
             map::FsckReport r;
             {
               py::gil_scoped_release unlock;
               r = s.Fsck();
             }
             py::dict d;
             PutFields(d, r, LTM_KV(r, ok), LTM_KV(r, problems), LTM_KV(r, sessions), LTM_KV(r, keyframes),
                       LTM_KV(r, blobs), LTM_KV(r, points), LTM_KV(r, bytes));
             return d;
           })
      .def("digest", &Store::Digest)
      .def("log", [](const Store& s) { return map::FormatLog(s); }, "The `ltmapper map log` table.")
      .def("__repr__", [](const Store& s) {
        return "<ltmapper.Store '" + s.path() + "' " + std::to_string(s.LatestSession() + 1) + " sessions>";
      });
  m.def(
      "write_labelled_cloud",
      [](const std::string& path, const py::object& cloud) { map::WriteLabelledCloud(path, CloudFromPython(cloud, path)); },
      py::arg("path"), py::arg("cloud"), "Writes a labelled cloud dict as .pcd or .ply (class / session / object fields).");
}

}  // namespace ltm::py_bind
