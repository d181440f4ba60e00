// ltmapper io: the one JSON writer and reader of the project (stage reports, eval reports, map
// objects): a small value, parser, pretty writer and the string quoting every hand-laid-out
// report uses. No third-party JSON library is a project dependency.
#pragma once

#include "ltmapper/core/core.hpp"

#include <map>
#include <memory>
#include <string>
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

// Pretty writer (2-space indent). Non-finite numbers are written as null.
class Writer {
 public:
  Writer& BeginObject(const std::string& key = {});
  Writer& EndObject();
  Writer& BeginArray(const std::string& key = {});
  Writer& EndArray();
  Writer& Number(const std::string& key, double v);
  Writer& Int(const std::string& key, long long v);
  Writer& String(const std::string& key, const std::string& v);
  Writer& Bool(const std::string& key, bool v);
  // Array elements (no key).
  Writer& Number(double v) { return Number({}, v); }
  std::string str() const { return out_ + "\n"; }

 private:
  void Prefix(const std::string& key);
  Writer& Open(const std::string& key, char bracket, bool object);  // a container: { or [
  Writer& Close(char bracket);
  std::string out_;
  std::vector<bool> first_;  // per open container: no element written yet
  std::vector<bool> is_object_;
};

// A JSON string literal: quotes, backslash, \n \r \t escaped, other control characters as \u00XX.
std::string Quote(const std::string& s);

}  // namespace ltm::io::json
