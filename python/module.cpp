// `import ltmapper`: Python bindings over ltmapper's public headers. Like the CLI, only type
// conversions (NumPy arrays, dicts, lists) around library calls; no algorithm lives here.
#include "convert.hpp"

#include "ltmapper/geometry/sensor.hpp"
#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

namespace ltm::py_bind {

void BindStages(py::module_& m);
void BindStore(py::module_& m);
void BindEval(py::module_& m);

namespace {

py::list EdgesToList(const std::vector<Edge>& edges) {
  py::list out;
  for (const auto& e : edges) {
    py::dict d;
    d["from"] = e.from;
    d["to"] = e.to;
    d["T_from_to"] = PoseToNumpy(e.T_from_to);
    if (e.has_information) {
      py::array_t<double> info({py::ssize_t(6), py::ssize_t(6)});
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) info.mutable_at(r, c) = e.information(r, c);
      d["information"] = info;
    } else {
      d["information"] = py::none();
    }
    out.append(d);
  }
  return out;
}

py::array_t<float> KeyframeScan(const Keyframe& kf) {
  std::shared_ptr<const PointCloud> c;
  {
    py::gil_scoped_release unlock;
    c = io::KeyframeCloud(kf);
  }
  return PointsToNumpy(*c);
}

std::vector<PointCloud> CloudsFromPython(const py::iterable& scans) {
  std::vector<PointCloud> out;
  for (auto s : scans) out.push_back(CloudFromPython(s, "scan " + std::to_string(out.size())));
  return out;
}

py::dict SensorToDict(const geometry::SensorModel& s) {
  py::dict d;
  d["source"] = s.source;
  d["ring_based"] = s.ring_based;
  d["beams"] = s.beams();
  PutFields(d, s, LTM_KV(s, elevations_deg), LTM_KV(s, azimuth_step_deg), LTM_KV(s, grid_deg), LTM_KV(s, fov_up_deg),
            LTM_KV(s, fov_down_deg), LTM_KV(s, spread_deg), LTM_KV(s, azimuth_center_deg),
            LTM_KV(s, azimuth_half_fov_deg));
  return d;
}

// Point clouds: read and write PCD, PLY, KITTI .bin.
void BindClouds(py::module_& m) {
  m.def(
      "read_cloud", [](const std::string& path) { return PointsToNumpy(io::ReadCloud(path)); }, py::arg("path"),
      "Reads a .pcd or KITTI .bin cloud as an (N,4) float32 array x y z intensity (NaN / Inf points dropped).");
  m.def(
      "read_ply", [](const std::string& path) { return CloudToDict(io::ReadPly(path)); }, py::arg("path"),
      "Reads a labelled PLY (as ltmapper writes it): {points (N,4) float32, cls uint8, session uint16, object int32}.");
  m.def(
      "write_pcd",
      [](const std::string& path, const py::object& cloud, const std::string& format) {
        io::PcdFormat f = io::PcdFormat::kBinary;
        if (format == "ascii") f = io::PcdFormat::kAscii;
        else if (format == "binary_compressed") f = io::PcdFormat::kBinaryCompressed;
        else if (format != "binary") throw py::value_error("write_pcd: format must be ascii, binary or binary_compressed");
        io::WritePcd(path, CloudFromPython(cloud, path), f);
      },
      py::arg("path"), py::arg("cloud"), py::arg("format") = "binary",
      "Writes an (N,3) / (N,4) array (x y z [intensity]) as PCD, atomically.");
  m.def(
      "write_ply", [](const std::string& path, const py::object& cloud) { io::WritePly(path, CloudFromPython(cloud, path)); },
      py::arg("path"), py::arg("cloud"),
      "Writes an array or a labelled cloud dict (cls / session / object fields) as binary PLY, atomically.");
  m.def(
      "write_kitti_bin", [](const std::string& path, const py::object& cloud) { io::WriteKittiBin(path, CloudFromPython(cloud, path)); },
      py::arg("path"), py::arg("cloud"));
}

// Pose files.
void BindPoses(py::module_& m) {
  m.def(
      "read_kitti_poses", [](const std::string& path) { return PosesToNumpy(io::ReadKittiPoses(path)); }, py::arg("path"),
      "KITTI pose file (12 numbers per line) as an (N,4,4) float64 array.");
  m.def(
      "write_kitti_poses",
      [](const std::string& path, const py::object& poses) { io::WriteKittiPoses(path, PosesFromPython(poses)); },
      py::arg("path"), py::arg("poses"));
  m.def(
      "read_transform", [](const std::string& path) { return PoseToNumpy(io::ReadTransform(path)); }, py::arg("path"),
      "A 3x4 / 4x4 rigid transform from a text file (e.g. KITTI's Tr) as a (4,4) array.");
}

// Session directories: load, inspect.
void BindSessions(py::module_& m) {
  py::class_<Keyframe>(m, "Keyframe", "One keyframe of a session: index, pose in the session frame, scan file.")
      .def_readonly("index", &Keyframe::index)
      .def_readonly("cloud_path", &Keyframe::cloud_path)
      .def_property_readonly("pose", [](const Keyframe& k) { return PoseToNumpy(k.T_session_sensor); },
                             "T_session_sensor as a (4,4) array.")
      .def_readonly("time_s", &Keyframe::time_s, "Timestamp [s] (times.txt or TUM stamps); NaN when unknown.")
      .def("scan", &KeyframeScan, "The scan (sensor frame, a raw sweep deskewed) as an (N,4) float32 array.")
      .def("__repr__", [](const Keyframe& k) { return "<ltmapper.Keyframe " + std::to_string(k.index) + ">"; });

  py::class_<Session>(m, "Session", "A session directory (SC-LIO-SAM layout or KITTI), as io::LoadSession reads it.")
      .def_readonly("name", &Session::name)
      .def_readonly("dir", &Session::dir)
      .def_readonly("keyframes", &Session::keyframes)
      .def_property_readonly(
          "poses",
          [](const Session& s) {
            std::vector<Pose> p;
            for (const auto& k : s.keyframes) p.push_back(k.T_session_sensor);
            return PosesToNumpy(p);
          },
          "Keyframe poses T_session_sensor as an (N,4,4) float64 array.")
      .def_property_readonly(
          "indices",
          [](const Session& s) {
            py::array_t<int> a(py::ssize_t(s.keyframes.size()));
            for (std::size_t i = 0; i < s.keyframes.size(); ++i) a.mutable_at(py::ssize_t(i)) = s.keyframes[i].index;
            return a;
          },
          "Keyframe indices (scan file numbers).")
      .def_property_readonly("odometry", [](const Session& s) { return EdgesToList(s.odometry); })
      .def_property_readonly("loops", [](const Session& s) { return EdgesToList(s.loops); })
      .def(
          "scan",
          [](const Session& s, int i) {
            const int n = int(s.keyframes.size());
            if (i < 0) i += n;
            if (i < 0 || i >= n) throw py::index_error("keyframe position out of range");
            return KeyframeScan(s.keyframes[std::size_t(i)]);
          },
          py::arg("i"), "Scan of the keyframe at position i (sensor frame) as an (N,4) float32 array.")
      .def(
          "scans",
          [](const Session& s) {
            py::list out;
            for (const auto& k : s.keyframes) out.append(KeyframeScan(k));
            return out;
          },
          "Every scan, in keyframe order.")
      .def("find", &Session::Find, py::arg("index"), "Position of the keyframe with this index, or -1.")
      .def("__len__", [](const Session& s) { return s.keyframes.size(); })
      .def("__repr__", [](const Session& s) {
        return "<ltmapper.Session '" + s.name + "' " + std::to_string(s.keyframes.size()) + " keyframes>";
      });

  m.def(
      "load_session",
      [](const std::string& dir, bool load_clouds, bool require_g2o) {
        io::SessionLoadOptions opt;
        opt.load_clouds = load_clouds;
        opt.require_g2o = require_g2o;
        py::gil_scoped_release unlock;
        return io::LoadSession(dir, opt);
      },
      py::arg("dir"), py::arg("load_clouds") = false, py::arg("require_g2o") = false,
      "Loads a session directory (Scans/NNNNNN.pcd + g2o and/or optimized_poses.txt).");
  m.def(
      "load_kitti_session",
      [](const std::string& dir, const std::string& poses_path, const py::object& T_cam_velo, bool load_clouds) {
        io::SessionLoadOptions opt;
        opt.load_clouds = load_clouds;
        Pose tr;
        const bool has_tr = !T_cam_velo.is_none();
        if (has_tr) tr = PoseFromPython(T_cam_velo, "T_cam_velo");
        py::gil_scoped_release unlock;
        return io::LoadKittiSession(dir, poses_path, has_tr ? &tr : nullptr, opt);
      },
      py::arg("dir"), py::arg("poses_path"), py::arg("T_cam_velo") = py::none(), py::arg("load_clouds") = false,
      "KITTI odometry layout (velodyne/NNNNNN.bin + poses file; T_cam_velo = KITTI's Tr as (4,4), optional).");
  m.def(
      "inspect_session",
      [](const std::string& dir, bool read_scans) { return io::FormatSessionInfo(io::InspectSession(dir, read_scans)); },
      py::arg("dir"), py::arg("read_scans") = true, "What `ltmapper info` prints about a session directory.");
}

// The sensor model: presets, beam tables, estimation from scans.
void BindSensor(py::module_& m) {
  py::class_<geometry::SensorModel>(m, "SensorModel", "What a LiDAR samples: beam elevations, azimuth step.")
      .def_readonly("source", &geometry::SensorModel::source)
      .def_readonly("ring_based", &geometry::SensorModel::ring_based)
      .def_readonly("elevations_deg", &geometry::SensorModel::elevations_deg)
      .def_readonly("azimuth_step_deg", &geometry::SensorModel::azimuth_step_deg)
      .def_readonly("grid_deg", &geometry::SensorModel::grid_deg)
      .def_readonly("fov_up_deg", &geometry::SensorModel::fov_up_deg)
      .def_readonly("fov_down_deg", &geometry::SensorModel::fov_down_deg)
      .def_readonly("spread_deg", &geometry::SensorModel::spread_deg)
      .def_readonly("azimuth_center_deg", &geometry::SensorModel::azimuth_center_deg)
      .def_readonly("azimuth_half_fov_deg", &geometry::SensorModel::azimuth_half_fov_deg)
      .def("in_azimuth_view", &geometry::SensorModel::InAzimuthView, py::arg("azimuth_deg"))
      .def_property_readonly("beams", &geometry::SensorModel::beams)
      .def("spacing_at", &geometry::SensorModel::SpacingAt, py::arg("elevation_deg"))
      .def("max_spacing", &geometry::SensorModel::MaxSpacing)
      .def("median_spacing", &geometry::SensorModel::MedianSpacing)
      .def("describe", &geometry::SensorModel::Describe)
      .def("to_dict", &SensorToDict)
      .def("__repr__", [](const geometry::SensorModel& s) { return "<ltmapper.SensorModel " + s.Describe() + ">"; });
  m.def("sensor_presets", &geometry::SensorPresetNames, "Names of the sensor presets.");
  m.def("sensor_preset", &geometry::SensorPreset, py::arg("name"), "A preset's real beam table (ltmapper.Error when unknown).");
  m.def(
      "sensor_from_table",
      [](const std::vector<double>& elevations_deg, double azimuth_step_deg) {
        return geometry::SensorFromTable(elevations_deg, azimuth_step_deg, "elevations_deg");
      },
      py::arg("elevations_deg"), py::arg("azimuth_step_deg") = 0.0);
  m.def(
      "estimate_sensor",
      [](const py::iterable& scans, double min_range_m, double bin_deg, double ring_fill_max) {
        const auto clouds = CloudsFromPython(scans);
        geometry::SensorEstimateOptions opt;
        opt.min_range_m = min_range_m;
        opt.bin_deg = bin_deg;
        opt.ring_fill_max = ring_fill_max;
        py::gil_scoped_release unlock;
        return geometry::EstimateSensor(clouds, opt);
      },
      py::arg("scans"), py::arg("min_range_m") = 3.0, py::arg("bin_deg") = 0.02, py::arg("ring_fill_max") = 0.5,
      "Estimates the sensor from a list of (N,3|4) scans in the sensor frame.");
}

// Files, poses, sessions and the sensor model.
void BindIo(py::module_& m) {
  BindClouds(m);
  BindPoses(m);
  BindSessions(m);
  BindSensor(m);
}

}  // namespace
}  // namespace ltm::py_bind

PYBIND11_MODULE(ltmapper, m) {
  namespace py = pybind11;
  using namespace ltm::py_bind;
  m.doc() =
      "ltmapper: LiDAR lifelong mapping (LT-SLAM, LT-removert, LT-map) from Python. Clouds are (N,4) float32 "
      "arrays x y z intensity (labelled clouds: dicts with cls / session / object arrays), poses (4,4) or (N,4,4) "
      "float64 arrays, results plain dicts. Library errors raise ltmapper.Error with the C++ message.";
  m.attr("__version__") = "0.1.0";
  py::register_exception<ltm::Error>(m, "Error", PyExc_RuntimeError);
  py::list names;
  for (int c = 0; c <= int(ltm::PointClass::kNDWeak); ++c) names.append(ltm::ToString(ltm::PointClass(c)));
  m.attr("CLASS_NAMES") = names;
  m.def(
      "set_log_level",
      [](const std::string& level) {
        const auto l = spdlog::level::from_str(level);
        if (l == spdlog::level::off && level != "off")
          throw py::value_error("log level: trace, debug, info, warn, error, critical or off");
        spdlog::set_level(l);
      },
      py::arg("level"), "Level of the library's log on stderr (trace ... off; default info).");
  BindConfigSection(m);
  BindIo(m);
  BindStages(m);
  BindStore(m);
  BindEval(m);
}
