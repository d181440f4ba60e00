// YAML params files <-> config fields (the Visit() list of a config struct). Nested maps are
// flattened to dotted keys ("lidar: {beams: 64}" is the key "lidar.beams"); a flat dotted key is
// accepted too. Unknown keys, wrong types and out-of-range values are errors naming file:line
// and key. Keys absent from the file (or a whole absent section) keep their defaults.
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/yaml.hpp"
#include "detail.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <climits>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>

namespace ltm::io {
namespace {

class Loader {
 public:
  // Values are staged and written to the config only when the whole file checked out, so a
  // bad file never leaves a config half-loaded.
  void Apply() const {
    for (const auto& set : pending_) set();
  }

  Loader(const std::string& path, const ConfigFields& fields) : path_(path) {
    for (const auto& f : fields.fields()) by_key_[f.key] = &f;
  }

  void Map(const YAML::Node& node, const std::string& prefix) {
    for (const auto& kv : node) {
      if (!kv.first.IsScalar()) throw Error(path_, Line(kv.first), "map keys must be plain names");
      const std::string key = prefix + kv.first.Scalar();
      auto it = by_key_.find(key);
      if (it != by_key_.end()) {
        Assign(*it->second, kv.second);
      } else if (kv.second.IsMap() && IsPrefix(key + ".")) {
        Map(kv.second, key + ".");
      } else {
        throw Error(path_, Line(kv.first), "unknown key '" + key + "' (valid keys: " + ValidKeys() + ")");
      }
    }
  }

 private:
  static std::size_t Line(const YAML::Node& n) { return std::size_t(n.Mark().line + 1); }

  bool IsPrefix(const std::string& p) const {
    auto it = by_key_.lower_bound(p);
    return it != by_key_.end() && it->first.compare(0, p.size(), p) == 0;
  }

  std::string ValidKeys() const {
    std::string s;
    for (const auto& kv : by_key_) s += (s.empty() ? "" : ", ") + kv.first;
    return s;
  }

  std::string Where(const ConfigField& f) const { return "key '" + f.key + "'"; }

  std::string Scalar(const ConfigField& f, const YAML::Node& n, const char* expected) const {
    if (!n.IsScalar())
      throw Error(path_, Line(n), Where(f) + ": expected " + std::string(expected) + ", got " +
                                      (n.IsSequence() ? "a list" : n.IsMap() ? "a map" : "nothing"));
    return n.Scalar();
  }

  double Number(const ConfigField& f, const YAML::Node& n) const {
    const std::string s = Scalar(f, n, "a number");
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (s.empty() || end == s.c_str() || *end != '\0' || errno == ERANGE || !std::isfinite(v))
      throw Error(path_, Line(n), Where(f) + ": expected a number, got '" + s + "'");
    return v;
  }

  void Range(const ConfigField& f, const YAML::Node& n, double v) const {
    if (v < f.lo || v > f.hi)
      throw Error(path_, Line(n), Where(f) + " = " + detail::FormatDouble(v) + " is out of range [" +
                                      detail::FormatDouble(f.lo) + ", " + detail::FormatDouble(f.hi) +
                                      "]" + (f.unit.empty() ? "" : " " + f.unit));
  }

  void Assign(const ConfigField& f, const YAML::Node& n) {
    switch (f.kind) {
      case ConfigField::Kind::kDouble: {
        const double v = Number(f, n);
        Range(f, n, v);
        pending_.push_back([&f, v] { *static_cast<double*>(f.ptr) = v; });
        break;
      }
      case ConfigField::Kind::kInt: {
        const std::string s = Scalar(f, n, "an integer");
        errno = 0;
        char* end = nullptr;
        const long v = std::strtol(s.c_str(), &end, 10);
        if (s.empty() || *end != '\0' || errno == ERANGE || v < INT_MIN || v > INT_MAX)
          throw Error(path_, Line(n), Where(f) + ": expected an integer, got '" + s + "'");
        Range(f, n, double(v));
        pending_.push_back([&f, v] { *static_cast<int*>(f.ptr) = int(v); });
        break;
      }
      case ConfigField::Kind::kBool: {
        const std::string s = Scalar(f, n, "true or false");
        bool v = false;
        if (!YAML::convert<bool>::decode(n, v))
          throw Error(path_, Line(n), Where(f) + ": expected true or false, got '" + s + "'");
        pending_.push_back([&f, v] { *static_cast<bool*>(f.ptr) = v; });
        break;
      }
      case ConfigField::Kind::kString: {
        const std::string s = Scalar(f, n, "a string");
        if (!f.choices.empty() && std::find(f.choices.begin(), f.choices.end(), s) == f.choices.end()) {
          std::string allowed;
          for (const auto& c : f.choices) allowed += (allowed.empty() ? "" : ", ") + c;
          throw Error(path_, Line(n), Where(f) + " = '" + s + "' is not one of: " + allowed);
        }
        pending_.push_back([&f, s] { *static_cast<std::string*>(f.ptr) = s; });
        break;
      }
      case ConfigField::Kind::kDoubleList: {
        if (!n.IsSequence())
          throw Error(path_, Line(n), Where(f) + ": expected a list of numbers like [1.0, 2.0]");
        std::vector<double> list;
        for (const auto& item : n) {
          const double v = Number(f, item);
          Range(f, item, v);
          list.push_back(v);
        }
        if (list.empty() && !f.allow_empty) throw Error(path_, Line(n), Where(f) + ": must not be an empty list");
        pending_.push_back([&f, list] { *static_cast<std::vector<double>*>(f.ptr) = list; });
        break;
      }
    }
  }

  std::string path_;
  std::map<std::string, const ConfigField*> by_key_;
  std::vector<std::function<void()>> pending_;  // applied only when the whole file is valid
};

// Tree of dotted keys for writing nested maps, in field order.
struct KeyTree {
  std::string name;
  const ConfigField* field = nullptr;
  std::vector<KeyTree> children;
  KeyTree& Child(const std::string& n) {
    for (auto& c : children)
      if (c.name == n && !c.field) return c;
    children.push_back({n, nullptr, {}});
    return children.back();
  }
};

void Emit(YAML::Emitter& out, const KeyTree& t) {
  out << YAML::BeginMap;
  for (const auto& c : t.children) {
    out << YAML::Key << c.name << YAML::Value;
    if (!c.field) {
      Emit(out, c);
      continue;
    }
    const ConfigField& f = *c.field;
    std::string comment = f.unit;
    switch (f.kind) {
      case ConfigField::Kind::kDouble: out << detail::FormatDouble(*static_cast<double*>(f.ptr)); break;
      case ConfigField::Kind::kInt: out << *static_cast<int*>(f.ptr); break;
      case ConfigField::Kind::kBool: out << (*static_cast<bool*>(f.ptr) ? "true" : "false"); break;
      case ConfigField::Kind::kString: {
        out << YAML::DoubleQuoted << *static_cast<std::string*>(f.ptr);
        if (!f.choices.empty()) {
          comment = "one of:";
          for (const auto& ch : f.choices) comment += " " + ch;
        }
        break;
      }
      case ConfigField::Kind::kDoubleList:
        out << YAML::Flow << YAML::BeginSeq;
        for (double v : *static_cast<std::vector<double>*>(f.ptr)) out << detail::FormatDouble(v);
        out << YAML::EndSeq;
        break;
    }
    if (f.kind == ConfigField::Kind::kDouble || f.kind == ConfigField::Kind::kInt ||
        f.kind == ConfigField::Kind::kDoubleList)
      comment += (comment.empty() ? "" : " ") + std::string("[") + detail::FormatDouble(f.lo) + ", " +
                 detail::FormatDouble(f.hi) + "]";
    if (!comment.empty()) out << YAML::Comment(comment);
  }
  out << YAML::EndMap;
}

}  // namespace

void LoadConfigFields(const std::string& path, const ConfigFields& fields, const std::string& section) {
  {
    std::ifstream probe(path);
    if (!probe) throw Error(path + ": cannot open params file (no such file or not readable)");
  }
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::ParserException& e) {
    throw Error(path, std::size_t(e.mark.line + 1), "malformed YAML: " + e.msg);
  } catch (const YAML::Exception& e) {
    throw Error(path + ": cannot read YAML: " + e.what());
  }
  if (!root || root.IsNull()) return;  // empty file: every key keeps its default
  if (!root.IsMap()) throw Error(path, std::size_t(root.Mark().line + 1), "top level must be a map of keys");
  YAML::Node node = root;
  if (!section.empty()) {
    node = root[section];
    if (!node || node.IsNull()) return;
    if (!node.IsMap())
      throw Error(path, std::size_t(node.Mark().line + 1), "section '" + section + "' must be a map");
  }
  Loader loader(path, fields);
  loader.Map(node, "");
  loader.Apply();
}

void SaveConfigFields(const std::string& path, const ConfigFields& fields) {
  KeyTree root;
  for (const auto& f : fields.fields()) {
    KeyTree* t = &root;
    std::string rest = f.key;
    for (auto dot = rest.find('.'); dot != std::string::npos; dot = rest.find('.')) {
      t = &t->Child(rest.substr(0, dot));
      rest = rest.substr(dot + 1);
    }
    t->children.push_back({rest, &f, {}});
  }
  YAML::Emitter out;
  Emit(out, root);
  if (!out.good()) throw Error(path + ": cannot format config as YAML: " + out.GetLastError());
  WriteFileAtomic(path, [&](std::ostream& os) { os << out.c_str() << "\n"; });
}

}  // namespace ltm::io
