#include "ltmapper/io/json.hpp"

#include "ltmapper/io/files.hpp"

#include <cmath>
#include <sstream>
#include <cstdio>
#include <cstdlib>

namespace ltm::io::json {

const Value* Value::Find(const std::string& key) const {
  if (type != Type::kObject) return nullptr;
  for (const auto& [k, v] : obj)
    if (k == key) return &v;
  return nullptr;
}

namespace {

// The short escapes: a character and the letter after its backslash. Quote writes the first five
// (other control characters as \u00XX); the parser reads all of them.
constexpr char kEscaped[] = {'"', '\\', '\n', '\r', '\t', '/', '\b', '\f'};
constexpr char kLetter[] = {'"', '\\', 'n', 'r', 't', '/', 'b', 'f'};
constexpr std::size_t kWritten = 5;

// Index of `c` in `table` (first `n` entries), or -1.
int Find(const char* table, std::size_t n, char c) {
  for (std::size_t i = 0; i < n; ++i)
    if (table[i] == c) return int(i);
  return -1;
}

class Parser {
 public:
  Parser(const std::string& text, const std::string& where) : s_(text), where_(where) {}

  Value ParseDocument() {
    Value v = ParseValue(0);
    SkipSpace();
    if (pos_ != s_.size()) Fail("unexpected trailing characters");
    return v;
  }

 private:
  [[noreturn]] void Fail(const std::string& what) const {
    throw Error(where_ + ": JSON error at offset " + std::to_string(pos_) + ": " + what);
  }
  void SkipSpace() {
    while (pos_ < s_.size() && (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\n' || s_[pos_] == '\r'))
      ++pos_;
  }
  char Peek() {
    SkipSpace();
    if (pos_ >= s_.size()) Fail("unexpected end of input");
    return s_[pos_];
  }
  void Expect(char c) {
    if (Peek() != c) Fail(std::string("expected '") + c + "'");
    ++pos_;
  }
  bool Literal(const char* lit) {
    const std::string l(lit);
    if (s_.compare(pos_, l.size(), l) == 0) {
      pos_ += l.size();
      return true;
    }
    return false;
  }

  // A container's items after its opening bracket, up to `close`; `item()` parses one.
  template <class Item>
  void Items(char close, Item&& item) {
    ++pos_;
    if (Peek() == close) {
      ++pos_;
      return;
    }
    for (;;) {
      item();
      const char n = Peek();
      ++pos_;
      if (n == close) break;
      if (n != ',') Fail(std::string("expected ',' or '") + close + "'");
    }
  }

  Value ParseValue(int depth) {
    if (depth > 256) Fail("nesting too deep");
    Value v;
    const char c = Peek();
    if (c == '{') {
      v.type = Value::Type::kObject;
      Items('}', [&] {
        if (Peek() != '"') Fail("expected a string key");
        std::string key = ParseString();
        Expect(':');
        v.obj.emplace_back(std::move(key), ParseValue(depth + 1));
      });
    } else if (c == '[') {
      v.type = Value::Type::kArray;
      Items(']', [&] { v.arr.push_back(ParseValue(depth + 1)); });
    } else if (c == '"') {
      v.type = Value::Type::kString;
      v.str = ParseString();
    } else if (Literal("true")) {
      v.type = Value::Type::kBool;
      v.b = true;
    } else if (Literal("false")) {
      v.type = Value::Type::kBool;
    } else if (Literal("null")) {
      v.type = Value::Type::kNull;
    } else {
      const char* begin = s_.c_str() + pos_;
      char* end = nullptr;
      v.num = std::strtod(begin, &end);
      if (end == begin || !(c == '-' || (c >= '0' && c <= '9'))) Fail("unexpected character");
      pos_ += std::size_t(end - begin);
      v.type = Value::Type::kNumber;
    }
    return v;
  }

  std::string ParseString() {
    ++pos_;  // opening quote
    std::string out;
    while (pos_ < s_.size()) {
      const char c = s_[pos_++];
      if (c == '"') return out;
      if (c != '\\') {
        out += c;
        continue;
      }
      if (pos_ >= s_.size()) break;
      const char e = s_[pos_++];
      if (const int k = Find(kLetter, sizeof(kLetter), e); k >= 0) {
        out += kEscaped[k];
        continue;
      }
      if (e != 'u') Fail("bad escape");
      if (pos_ + 4 > s_.size()) Fail("short \\u escape");
      const unsigned cp = unsigned(std::strtoul(s_.substr(pos_, 4).c_str(), nullptr, 16));
      pos_ += 4;
      // UTF-8 encode (surrogate pairs are kept as two code units; fine for our keys).
      if (cp < 0x80) {
        out += char(cp);
      } else if (cp < 0x800) {
        out += char(0xC0 | (cp >> 6));
        out += char(0x80 | (cp & 0x3F));
      } else {
        out += char(0xE0 | (cp >> 12));
        out += char(0x80 | ((cp >> 6) & 0x3F));
        out += char(0x80 | (cp & 0x3F));
      }
    }
    Fail("unterminated string");
  }

  const std::string& s_;
  std::string where_;
  std::size_t pos_ = 0;
};

}  // namespace

Value Parse(const std::string& text, const std::string& where) {
  return Parser(text, where).ParseDocument();
}

Value ParseFile(const std::string& path) { return Parse(ReadFileText(path), path); }

std::string Quote(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    if (const int k = Find(kEscaped, kWritten, c); k >= 0) {
      out += '\\';
      out += kLetter[k];
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\u%04x", unsigned(c));
      out += buf;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

void Writer::Prefix(const std::string& key) {
  if (!first_.empty()) {
    if (!first_.back()) out_ += ",";
    first_.back() = false;
    out_ += "\n" + std::string(2 * first_.size(), ' ');
    if (is_object_.back()) out_ += Quote(key) + ": ";
  }
}

Writer& Writer::Open(const std::string& key, char bracket, bool object) {
  Prefix(key);
  out_ += bracket;
  first_.push_back(true);
  is_object_.push_back(object);
  return *this;
}

Writer& Writer::Close(char bracket) {
  const bool empty = first_.back();
  first_.pop_back();
  is_object_.pop_back();
  if (!empty) out_ += "\n" + std::string(2 * first_.size(), ' ');
  out_ += bracket;
  return *this;
}

Writer& Writer::BeginObject(const std::string& key) { return Open(key, '{', true); }
Writer& Writer::EndObject() { return Close('}'); }
Writer& Writer::BeginArray(const std::string& key) { return Open(key, '[', false); }
Writer& Writer::EndArray() { return Close(']'); }

Writer& Writer::Number(const std::string& key, double v) {
  Prefix(key);
  if (!std::isfinite(v)) {
    out_ += "null";
  } else {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.10g", v);
    out_ += buf;
  }
  return *this;
}

Writer& Writer::Int(const std::string& key, long long v) {
  Prefix(key);
  out_ += std::to_string(v);
  return *this;
}

Writer& Writer::String(const std::string& key, const std::string& v) {
  Prefix(key);
  out_ += Quote(v);
  return *this;
}

Writer& Writer::Bool(const std::string& key, bool v) {
  Prefix(key);
  out_ += v ? "true" : "false";
  return *this;
}

}  // namespace ltm::io::json
