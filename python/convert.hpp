// Internal to the Python bindings: conversions between ltmapper's public types and Python
// (NumPy arrays, dicts, lists) and the generic binding of Visit()-configs. No algorithm here.
#pragma once

#include "ltmapper/core/core.hpp"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <type_traits>
#include <vector>

namespace ltm::py_bind {

namespace py = pybind11;

// ------------------------------------------------------------------------------------ clouds
// (N,4) float32: x y z intensity.
py::array_t<float> PointsToNumpy(const PointCloud& cloud);
// {"points": (N,4) float32, and "cls" uint8 / "session" uint16 / "object" int32 when present}.
py::dict CloudToDict(const PointCloud& cloud);
// Accepts an (N,3) or (N,4) array (anything NumPy converts to float32) or a dict as CloudToDict
// writes it ("points" required; "cls", "session", "object" optional, each N long).
PointCloud CloudFromPython(const py::handle& obj, const std::string& what = "cloud");

// ------------------------------------------------------------------------------------- poses
py::array_t<double> PoseToNumpy(const Pose& pose);                   // (4,4)
py::array_t<double> PosesToNumpy(const std::vector<Pose>& poses);    // (N,4,4)
Pose PoseFromPython(const py::handle& obj, const std::string& what = "pose");
std::vector<Pose> PosesFromPython(const py::handle& obj, const std::string& what = "poses");

// ------------------------------------------------------------------------------ result dicts
// The plain fields of a result struct into a dict under their own names, in one call:
//   PutFields(d, r, LTM_KV(r, session), LTM_KV(r, points), LTM_KV(r, seconds));
// is d["session"] = r.session; d["points"] = r.points; d["seconds"] = r.seconds (pybind11's
// conversions: numbers, strings, bools, std::vector of them). Fields needing a conversion of
// their own (poses, vectors, nested records) are set beside it.
#define LTM_KV(obj, field) #field, &std::decay_t<decltype(obj)>::field
template <class S>
void PutFields(py::dict&, const S&) {}
template <class S, class T, class... Rest>
void PutFields(py::dict& d, const S& s, const char* name, T S::*member, Rest... rest) {
  d[name] = s.*member;
  PutFields(d, s, rest...);
}

// --------------------------------------------------------------------------------- JSON / misc
// json.loads(text) (the eval module's report JSON as plain dicts; NaN is written as null).
py::object JsonLoads(const std::string& text);
const char* ClassName(PointClass c);

// ------------------------------------------------------------------------------------ configs
// Value of a config field as a Python object, and assignment with type and range checks (the
// field's own range; cross-field rules are checked when a stage runs or by validate()).
py::object FieldValue(const ConfigField& f);
void SetFieldValue(const ConfigField& f, const py::handle& value, const std::string& where);
// Range check of one field (ValidateFields on a one-field list).
void ValidateOneField(const ConfigField& f, const std::string& where);

// Attribute access to dotted keys: cfg.hd.dilate_voxels is the key "hd.dilate_voxels".
// `config` is the bound config object; get/set go through its "get" and "set" methods.
struct ConfigSection {
  py::object config;
  std::string prefix;  // "hd."
};
void BindConfigSection(py::module_& m);

}  // namespace ltm::py_bind
