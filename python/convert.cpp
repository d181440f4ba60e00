// Conversions between ltmapper types and Python objects (see convert.hpp).
#include "convert.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

namespace ltm::py_bind {

static_assert(sizeof(PointXYZI) == 4 * sizeof(float), "PointXYZI must be 4 packed floats");

py::array_t<float> PointsToNumpy(const PointCloud& cloud) {
  py::array_t<float> a({py::ssize_t(cloud.size()), py::ssize_t(4)});
  if (!cloud.empty()) std::memcpy(a.mutable_data(), cloud.points.data(), cloud.size() * sizeof(PointXYZI));
  return a;
}

template <class T, class U>
static py::array_t<T> VectorToNumpy(const std::vector<U>& v) {
  py::array_t<T> a(py::ssize_t(v.size()));
  T* d = a.mutable_data();
  for (std::size_t i = 0; i < v.size(); ++i) d[i] = T(v[i]);
  return a;
}

py::dict CloudToDict(const PointCloud& cloud) {
  py::dict d;
  d["points"] = PointsToNumpy(cloud);
  if (!cloud.cls.empty()) d["cls"] = VectorToNumpy<std::uint8_t>(cloud.cls);
  if (!cloud.session.empty()) d["session"] = VectorToNumpy<std::uint16_t>(cloud.session);
  if (!cloud.object.empty()) d["object"] = VectorToNumpy<std::int32_t>(cloud.object);
  return d;
}

template <class T>
static std::vector<T> ColumnFromPython(const py::handle& obj, std::size_t n, const std::string& what) {
  auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(obj);
  if (!a || a.ndim() != 1 || std::size_t(a.shape(0)) != n)
    throw py::value_error(what + ": expected a 1-D array of " + std::to_string(n) + " values");
  return std::vector<T>(a.data(), a.data() + n);
}

PointCloud CloudFromPython(const py::handle& obj, const std::string& what) {
  PointCloud c;
  py::handle pts = obj;
  if (py::isinstance<py::dict>(obj)) {
    const py::dict d = py::reinterpret_borrow<py::dict>(obj);
    if (!d.contains("points")) throw py::value_error(what + ": a cloud dict needs \"points\"");
    pts = d["points"];
  }
  auto a = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(pts);
  if (!a || a.ndim() != 2 || (a.shape(1) != 3 && a.shape(1) != 4))
    throw py::value_error(what + ": expected an (N,3) or (N,4) array (x y z [intensity])");
  const std::size_t n = std::size_t(a.shape(0)), k = std::size_t(a.shape(1));
  c.points.resize(n);
  const float* s = a.data();
  if (k == 4) {
    if (n) std::memcpy(static_cast<void*>(c.points.data()), s, n * sizeof(PointXYZI));
  } else {
    for (std::size_t i = 0; i < n; ++i) c.points[i] = {s[3 * i], s[3 * i + 1], s[3 * i + 2], 0.f};
  }
  if (py::isinstance<py::dict>(obj)) {
    const py::dict d = py::reinterpret_borrow<py::dict>(obj);
    if (d.contains("cls")) {
      for (auto v : ColumnFromPython<std::uint8_t>(d["cls"], n, what + "[\"cls\"]")) {
        if (v > std::uint8_t(PointClass::kNDWeak)) throw py::value_error(what + ": class value " + std::to_string(v) + " out of range 0..6");
        c.cls.push_back(PointClass(v));
      }
    }
    if (d.contains("session")) c.session = ColumnFromPython<std::uint16_t>(d["session"], n, what + "[\"session\"]");
    if (d.contains("object")) c.object = ColumnFromPython<std::int32_t>(d["object"], n, what + "[\"object\"]");
  }
  return c;
}

py::array_t<double> PoseToNumpy(const Pose& pose) {
  py::array_t<double> a({py::ssize_t(4), py::ssize_t(4)});
  double* d = a.mutable_data();
  const Eigen::Matrix4d m = pose.matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) d[4 * r + c] = m(r, c);
  return a;
}

py::array_t<double> PosesToNumpy(const std::vector<Pose>& poses) {
  py::array_t<double> a({py::ssize_t(poses.size()), py::ssize_t(4), py::ssize_t(4)});
  double* d = a.mutable_data();
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const Eigen::Matrix4d m = poses[i].matrix();
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) d[16 * i + 4 * r + c] = m(r, c);
  }
  return a;
}

static Pose PoseFromRowMajor(const double* d, const std::string& what) {
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      if (!std::isfinite(d[4 * r + c])) throw py::value_error(what + ": non-finite value");
      m(r, c) = d[4 * r + c];
    }
  Pose p = Pose::Identity();
  p.linear() = m.topLeftCorner<3, 3>();
  p.translation() = m.topRightCorner<3, 1>();
  return p;
}

Pose PoseFromPython(const py::handle& obj, const std::string& what) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(obj);
  if (!a || a.ndim() != 2 || a.shape(0) != 4 || a.shape(1) != 4) throw py::value_error(what + ": expected a (4,4) array");
  return PoseFromRowMajor(a.data(), what);
}

std::vector<Pose> PosesFromPython(const py::handle& obj, const std::string& what) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(obj);
  if (!a || a.ndim() != 3 || a.shape(1) != 4 || a.shape(2) != 4)
    throw py::value_error(what + ": expected an (N,4,4) array");
  std::vector<Pose> poses;
  for (py::ssize_t i = 0; i < a.shape(0); ++i)
    poses.push_back(PoseFromRowMajor(a.data() + 16 * i, what + "[" + std::to_string(i) + "]"));
  return poses;
}

py::object JsonLoads(const std::string& text) { return py::module_::import("json").attr("loads")(text); }

const char* ClassName(PointClass c) { return ToString(c); }

// ------------------------------------------------------------------------------------ configs
py::object FieldValue(const ConfigField& f) {
  switch (f.kind) {
    case ConfigField::Kind::kDouble: return py::float_(*static_cast<double*>(f.ptr));
    case ConfigField::Kind::kInt: return py::int_(*static_cast<int*>(f.ptr));
    case ConfigField::Kind::kBool: return py::bool_(*static_cast<bool*>(f.ptr));
    case ConfigField::Kind::kString: return py::str(*static_cast<std::string*>(f.ptr));
    case ConfigField::Kind::kDoubleList: return py::cast(*static_cast<std::vector<double>*>(f.ptr));
  }
  return py::none();
}

static std::string TypeName(ConfigField::Kind k) {
  switch (k) {
    case ConfigField::Kind::kDouble: return "a number";
    case ConfigField::Kind::kInt: return "an integer";
    case ConfigField::Kind::kBool: return "True or False";
    case ConfigField::Kind::kString: return "a string";
    case ConfigField::Kind::kDoubleList: return "a list of numbers";
  }
  return "?";
}

void ValidateOneField(const ConfigField& f, const std::string& where) {
  ConfigFields one;
  switch (f.kind) {
    case ConfigField::Kind::kDouble: one(f.key, *static_cast<double*>(f.ptr), f.unit, f.lo, f.hi); break;
    case ConfigField::Kind::kInt: one(f.key, *static_cast<int*>(f.ptr), f.unit, int(f.lo), int(f.hi)); break;
    case ConfigField::Kind::kBool: one(f.key, *static_cast<bool*>(f.ptr)); break;
    case ConfigField::Kind::kString: one(f.key, *static_cast<std::string*>(f.ptr), f.choices); break;
    case ConfigField::Kind::kDoubleList:
      one(f.key, *static_cast<std::vector<double>*>(f.ptr), f.unit, f.lo, f.hi, f.allow_empty);
      break;
  }
  ValidateFields(one, where);
}

void SetFieldValue(const ConfigField& f, const py::handle& value, const std::string& where) {
  const std::string bad = where + ": " + f.key + " must be " + TypeName(f.kind);
  const bool is_bool = py::isinstance<py::bool_>(value);
  const py::object old = FieldValue(f);
  auto restore = [&] {
    switch (f.kind) {
      case ConfigField::Kind::kDouble: *static_cast<double*>(f.ptr) = py::cast<double>(old); break;
      case ConfigField::Kind::kInt: *static_cast<int*>(f.ptr) = py::cast<int>(old); break;
      case ConfigField::Kind::kBool: *static_cast<bool*>(f.ptr) = py::cast<bool>(old); break;
      case ConfigField::Kind::kString: *static_cast<std::string*>(f.ptr) = py::cast<std::string>(old); break;
      case ConfigField::Kind::kDoubleList:
        *static_cast<std::vector<double>*>(f.ptr) = py::cast<std::vector<double>>(old);
        break;
    }
  };
  try {
    switch (f.kind) {
      case ConfigField::Kind::kDouble:
        if (is_bool || !(py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value) ||
                         py::hasattr(value, "__float__")))
          throw py::type_error(bad);
        *static_cast<double*>(f.ptr) = py::cast<double>(value);
        break;
      case ConfigField::Kind::kInt: {
        if (is_bool || !py::hasattr(value, "__index__")) throw py::type_error(bad);
        const long long v = py::cast<long long>(py::reinterpret_borrow<py::object>(value).attr("__index__")());
        if (v < -2147483648LL || v > 2147483647LL) throw py::value_error(where + ": " + f.key + " out of range");
        *static_cast<int*>(f.ptr) = int(v);
        break;
      }
      case ConfigField::Kind::kBool:
        if (!is_bool) throw py::type_error(bad);
        *static_cast<bool*>(f.ptr) = py::cast<bool>(value);
        break;
      case ConfigField::Kind::kString:
        if (!py::isinstance<py::str>(value)) throw py::type_error(bad);
        *static_cast<std::string*>(f.ptr) = py::cast<std::string>(value);
        break;
      case ConfigField::Kind::kDoubleList: {
        if (py::isinstance<py::str>(value) || !py::isinstance<py::sequence>(value)) throw py::type_error(bad);
        std::vector<double> v;
        for (auto item : py::reinterpret_borrow<py::sequence>(value)) {
          if (py::isinstance<py::bool_>(item) || !py::hasattr(item, "__float__")) throw py::type_error(bad);
          v.push_back(py::cast<double>(item));
        }
        *static_cast<std::vector<double>*>(f.ptr) = v;
        break;
      }
    }
  } catch (const py::cast_error&) {
    throw py::type_error(bad);
  }
  try {
    ValidateOneField(f, where);
  } catch (...) {
    restore();
    throw;
  }
}

void BindConfigSection(py::module_& m) {
  py::class_<ConfigSection>(m, "ConfigSection", "A section of a config's dotted keys (cfg.hd is the keys \"hd.*\").")
      .def("__getattr__",
           [](const ConfigSection& s, const std::string& attr) -> py::object {
             const std::string key = s.prefix + attr;
             const py::list keys = s.config.attr("keys")();
             for (auto k : keys) {
               const std::string ks = py::cast<std::string>(k);
               if (ks == key) return s.config.attr("get")(key);
             }
             for (auto k : keys)
               if (py::cast<std::string>(k).rfind(key + ".", 0) == 0) return py::cast(ConfigSection{s.config, key + "."});
             throw py::attribute_error("no key or section '" + key + "'");
           })
      .def("__setattr__",
           [](const ConfigSection& s, const std::string& attr, const py::object& value) {
             s.config.attr("set")(s.prefix + attr, value);
           })
      .def("__dir__",
           [](const ConfigSection& s) {
             std::vector<std::string> names;
             for (auto k : py::list(s.config.attr("keys")())) {
               const std::string ks = py::cast<std::string>(k);
               if (ks.rfind(s.prefix, 0) != 0) continue;
               const std::string rest = ks.substr(s.prefix.size());
               const std::string top = rest.substr(0, rest.find('.'));
               if (std::find(names.begin(), names.end(), top) == names.end()) names.push_back(top);
             }
             return names;
           })
      .def("to_dict",
           [](const ConfigSection& s) {
             py::dict d;
             const py::dict all = s.config.attr("to_dict")();
             for (auto kv : all) {
               const std::string k = py::cast<std::string>(kv.first);
               if (k.rfind(s.prefix, 0) == 0) d[py::str(k.substr(s.prefix.size()))] = kv.second;
             }
             return d;
           })
      .def("__repr__", [](const ConfigSection& s) {
        return "<ltmapper config section '" + s.prefix.substr(0, s.prefix.size() - 1) + "'>";
      });
}

}  // namespace ltm::py_bind
