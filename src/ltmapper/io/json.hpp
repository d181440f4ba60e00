// ltmapper io: the one JSON writer and reader of the project (stage reports, eval reports, map
// objects): a small value, parser and pretty writer, on nlohmann-json (its header only in
// json.cpp).
#pragma once

#include "ltmapper/core/core.hpp"

#include <map>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace ltm::io::json {

struct Value {
  enum class Type { kNull, kBool, kNumber, kString, kArray, kObject };
  Type type = Type::kNull;
  bool b = false;
  double num = 0.0;
  std::string str;
  std::vector<Value> arr;
  std::vector<std::pair<std::string, Value>> obj;  // document order

  const Value* Find(const std::string& key) const;
};

// Throws ltm::Error("<where>: JSON error at offset N: ...") on malformed input.
Value Parse(const std::string& text, const std::string& where);
// The JSON file at `path`; ltm::Error naming it when it cannot be read or is malformed.
Value ParseFile(const std::string& path);

// Pretty writer (2-space indent), building the document in order. Non-finite numbers are written
// as null; a value outside any object or array, or an End without a Begin, is an ltm::Error.
class Writer {
 public:
  Writer();
  ~Writer();
  Writer(Writer&&) noexcept;
  Writer& operator=(Writer&&) noexcept;
  Writer& BeginObject(const std::string& key = {});
  Writer& EndObject();
  Writer& BeginArray(const std::string& key = {});
  Writer& EndArray();
  Writer& Number(const std::string& key, double v);
  Writer& Int(const std::string& key, long long v);
  template <class I, class = std::enable_if_t<std::is_integral_v<I> && !std::is_same_v<I, bool>>>
  Writer& Int(const std::string& key, I v) {  // any count or size
    return Int(key, static_cast<long long>(v));
  }
  Writer& String(const std::string& key, const std::string& v);
  Writer& Bool(const std::string& key, bool v);
  Writer& Null(const std::string& key);
  // Array elements (no key).
  Writer& Number(double v) { return Number({}, v); }
  Writer& Int(long long v) { return Int({}, v); }
  std::string str() const;

 private:
  struct Tree;
  Writer& Open(const std::string& key, bool object);  // a container: object or array
  Writer& Close();
  std::unique_ptr<Tree> tree_;
};

}  // namespace ltm::io::json
