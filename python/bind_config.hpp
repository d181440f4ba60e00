// Internal to the Python bindings: one Python class per Visit()-config (SlamConfig, ...). Every
// key is an attribute (dotted keys as sections: cfg.hd.dilate_voxels), plus get / set / keys /
// to_dict / from_yaml / save_yaml / validate / copy. Reading YAML, "key=value" overrides and
// validation are the library's (io::LoadConfig, SetField, the config's own checks).
#pragma once

#include "convert.hpp"

#include "ltmapper/io/io.hpp"

#include <algorithm>
#include <functional>
#include <string>

namespace ltm::py_bind {

template <class C>
const ConfigField* FindField(const ConfigFields& fields, const std::string& key) {
  for (const auto& f : fields.fields())
    if (f.key == key) return &f;
  return nullptr;
}

inline bool HasSection(const ConfigFields& fields, const std::string& prefix) {
  for (const auto& f : fields.fields())
    if (f.key.rfind(prefix, 0) == 0) return true;
  return false;
}

// `validate(cfg, where)`: the checks the CLI runs before the stage (ranges + cross-field rules).
template <class C>
py::class_<C> BindConfig(py::module_& m, const char* name, const char* doc,
                         std::function<void(const C&, const std::string&)> validate) {
  py::class_<C> cls(m, name, doc);
  const std::string where = std::string(name);
  cls.def(py::init([where](const py::object& values) {
            C c;
            if (!values.is_none()) {
              for (const auto& kv : py::cast<py::dict>(values)) {
                const std::string key = py::cast<std::string>(kv.first);
                auto fields = FieldsOf(c);
                const ConfigField* f = FindField<C>(fields, key);
                if (!f) throw Error(where + ": unknown key '" + key + "'");
                SetFieldValue(*f, kv.second, where);
              }
            }
            return c;
          }),
          py::arg("values") = py::none(),
          "Defaults, with the keys of the optional dict {\"dotted.key\": value} set.");
  cls.def_static(
      "from_yaml",
      [validate](const std::string& path, const std::string& section) {
        C c;
        io::LoadConfig(path, c, section);
        validate(c, path);
        return c;
      },
      py::arg("path"), py::arg("section") = "",
      "Reads a params YAML file (unknown keys, wrong types and out-of-range values raise ltmapper.Error).");
  cls.def(
      "get",
      [where](C& c, const std::string& key) {
        auto fields = FieldsOf(c);
        const ConfigField* f = FindField<C>(fields, key);
        if (!f) throw Error(where + ": unknown key '" + key + "'");
        return FieldValue(*f);
      },
      py::arg("key"), "Value of a dotted key.");
  cls.def(
      "set",
      [where](C& c, const std::string& key_value) {
        auto fields = FieldsOf(c);
        const std::string key = key_value.substr(0, key_value.find('='));
        const ConfigField* f = FindField<C>(fields, key);
        const py::object old = f ? FieldValue(*f) : py::none();
        SetField(fields, key_value);  // unknown keys and unparsable values: ltm::Error
        try {
          ValidateOneField(*f, where);
        } catch (...) {
          SetFieldValue(*f, old, where);
          throw;
        }
      },
      py::arg("key_value"), "Applies one \"key=value\" override, as the CLI's --set does.");
  cls.def(
      "set",
      [where](C& c, const std::string& key, const py::object& value) {
        auto fields = FieldsOf(c);
        const ConfigField* f = FindField<C>(fields, key);
        if (!f) throw Error(where + ": unknown key '" + key + "'");
        SetFieldValue(*f, value, where);
      },
      py::arg("key"), py::arg("value"), "Sets a dotted key to a Python value (type and range checked).");
  cls.def("keys", [](C& c) {
    std::vector<std::string> keys;
    const auto fields = FieldsOf(c);
    for (const auto& f : fields.fields()) keys.push_back(f.key);
    return keys;
  });
  cls.def(
      "to_dict",
      [](C& c) {
        py::dict d;
        const auto fields = FieldsOf(c);
        for (const auto& f : fields.fields()) d[py::str(f.key)] = FieldValue(f);
        return d;
      },
      "{\"dotted.key\": value} for every key.");
  cls.def(
      "validate", [validate, where](const C& c) { validate(c, where); },
      "Range checks plus the cross-field rules the stage applies (raises ltmapper.Error).");
  cls.def(
      "save_yaml", [](C& c, const std::string& path) { io::SaveConfigFields(path, FieldsOf(c)); },
      py::arg("path"), "Writes the config as YAML (nested maps for dotted keys).");
  cls.def("copy", [](const C& c) { return C(c); });
  cls.def("__copy__", [](const C& c) { return C(c); });
  cls.def("__deepcopy__", [](const C& c, py::dict) { return C(c); });
  cls.def("__eq__", [](C& a, C& b) { return ConfigToString(a) == ConfigToString(b); });
  cls.def("__str__", [](const C& c) { return ConfigToString(c); });
  cls.def("__repr__", [name](const C& c) {
    std::string s = ConfigToString(c);
    return "<ltmapper." + std::string(name) + ">\n" + s;
  });
  cls.def("__getattr__", [where](py::object self, const std::string& attr) -> py::object {
    C& c = py::cast<C&>(self);
    auto fields = FieldsOf(c);
    if (const ConfigField* f = FindField<C>(fields, attr)) return FieldValue(*f);
    if (HasSection(fields, attr + ".")) return py::cast(ConfigSection{self, attr + "."});
    throw py::attribute_error(where + " has no key or section '" + attr + "'");
  });
  cls.def("__setattr__", [where](C& c, const std::string& attr, const py::object& value) {
    auto fields = FieldsOf(c);
    const ConfigField* f = FindField<C>(fields, attr);
    if (!f) throw py::attribute_error(where + " has no key '" + attr + "' (sections: assign cfg.section.key)");
    SetFieldValue(*f, value, where);
  });
  cls.def("__dir__", [](C& c) {
    std::vector<std::string> names = {"get", "set", "keys", "to_dict", "from_yaml", "save_yaml", "validate", "copy"};
    const auto fields = FieldsOf(c);
    for (const auto& f : fields.fields()) {
      const std::string top = f.key.substr(0, f.key.find('.'));
      if (std::find(names.begin(), names.end(), top) == names.end()) names.push_back(top);
    }
    return names;
  });
  return cls;
}

}  // namespace ltm::py_bind
