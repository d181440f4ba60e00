// The project's JSON on nlohmann-json (nlohmann-json3-dev): its parser and writer behind the small
// io::json interface, so its header stays in this file.
#include "ltmapper/io/json.hpp"

#include "ltmapper/io/files.hpp"

#include <nlohmann/json.hpp>

#include <cmath>

namespace ltm::io::json {

const Value* Value::Find(const std::string& key) const {
  if (type != Type::kObject) return nullptr;
  for (const auto& [k, v] : obj)
    if (k == key) return &v;
  return nullptr;
}

namespace {

using Json = nlohmann::ordered_json;

// Deeper documents are an error (a hostile file must not exhaust the stack of ToValue).
constexpr int kMaxDepth = 256;

Value ToValue(const Json& j) {
  Value v;
  switch (j.type()) {
    case Json::value_t::object:
      v.type = Value::Type::kObject;
      for (const auto& [k, item] : j.items()) v.obj.emplace_back(k, ToValue(item));
      break;
    case Json::value_t::array:
      v.type = Value::Type::kArray;
      for (const auto& item : j) v.arr.push_back(ToValue(item));
      break;
    case Json::value_t::string:
      v.type = Value::Type::kString;
      v.str = j.get<std::string>();
      break;
    case Json::value_t::boolean:
      v.type = Value::Type::kBool;
      v.b = j.get<bool>();
      break;
    case Json::value_t::number_integer:
    case Json::value_t::number_unsigned:
    case Json::value_t::number_float:
      v.type = Value::Type::kNumber;
      v.num = j.get<double>();
      break;
    default:  // null, discarded, binary (not produced by the text parser)
      break;
  }
  return v;
}

// `j` as text; bytes of its strings that are not UTF-8 become U+FFFD.
std::string Dump(const Json& j, int indent) { return j.dump(indent, ' ', false, Json::error_handler_t::replace); }

}  // namespace

Value Parse(const std::string& text, const std::string& where) {
  const Json::parser_callback_t depth_limit = [&](int depth, Json::parse_event_t, Json&) {
    if (depth > kMaxDepth) throw Error(where + ": JSON error: nesting deeper than " + std::to_string(kMaxDepth));
    return true;
  };
  try {
    return ToValue(Json::parse(text, depth_limit));
  } catch (const Json::parse_error& e) {
    throw Error(where + ": JSON error at offset " + std::to_string(e.byte) + ": " + e.what());
  } catch (const Json::exception& e) {  // e.g. a number beyond double's range
    throw Error(where + ": JSON error: " + e.what());
  }
}

Value ParseFile(const std::string& path) { return Parse(ReadFileText(path), path); }

// The document a Writer builds: its root and the containers begun and not yet ended.
struct Writer::Tree {
  Json root;
  std::vector<Json*> open;  // innermost last

  // Adds `value` to the innermost open container (under `key` in an object); returns it.
  Json* Put(const std::string& key, Json value) {
    if (open.empty()) throw Error("json::Writer: a value outside any object or array");
    Json& parent = *open.back();
    if (!parent.is_array()) return &(parent[key] = std::move(value));
    parent.push_back(std::move(value));
    return &parent.back();
  }
};

Writer::Writer() : tree_(std::make_unique<Tree>()) {}
Writer::~Writer() = default;
Writer::Writer(Writer&&) noexcept = default;
Writer& Writer::operator=(Writer&&) noexcept = default;

Writer& Writer::Open(const std::string& key, bool object) {
  Json container = object ? Json::object() : Json::array();
  if (tree_->open.empty()) {
    tree_->root = std::move(container);
    tree_->open.push_back(&tree_->root);
  } else {
    tree_->open.push_back(tree_->Put(key, std::move(container)));
  }
  return *this;
}

Writer& Writer::Close() {
  if (tree_->open.empty()) throw Error("json::Writer: End without Begin");
  tree_->open.pop_back();
  return *this;
}

Writer& Writer::BeginObject(const std::string& key) { return Open(key, true); }
Writer& Writer::EndObject() { return Close(); }
Writer& Writer::BeginArray(const std::string& key) { return Open(key, false); }
Writer& Writer::EndArray() { return Close(); }

Writer& Writer::Number(const std::string& key, double v) {
  tree_->Put(key, std::isfinite(v) ? Json(v) : Json());
  return *this;
}
Writer& Writer::Int(const std::string& key, long long v) {
  tree_->Put(key, Json(v));
  return *this;
}
Writer& Writer::String(const std::string& key, const std::string& v) {
  tree_->Put(key, Json(v));
  return *this;
}
Writer& Writer::Bool(const std::string& key, bool v) {
  tree_->Put(key, Json(v));
  return *this;
}

Writer& Writer::Null(const std::string& key) {
  tree_->Put(key, Json());
  return *this;
}

std::string Writer::str() const { return Dump(tree_->root, 2) + "\n"; }

}  // namespace ltm::io::json
