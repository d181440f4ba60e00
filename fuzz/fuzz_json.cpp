// The JSON reader (io::json::ParseFile: the stages' report.json read by eval and `add`) on
// arbitrary bytes, then the Writer on what it read (a parsed document is written back).
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"

namespace {
// Writes v back with the Writer, under `key` inside an open container.
void WriteBack(ltm::io::json::Writer& w, const std::string& key, const ltm::io::json::Value& v) {
  using T = ltm::io::json::Value::Type;
  switch (v.type) {
    case T::kObject:
      w.BeginObject(key);
      for (const auto& [k, item] : v.obj) WriteBack(w, k, item);
      w.EndObject();
      break;
    case T::kArray:
      w.BeginArray(key);
      for (const auto& item : v.arr) WriteBack(w, {}, item);
      w.EndArray();
      break;
    case T::kString: w.String(key, v.str); break;
    case T::kBool: w.Bool(key, v.b); break;
    case T::kNumber: w.Number(key, v.num); break;
    case T::kNull: w.Null(key); break;
  }
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".json");
  ltm::fuzz::Expect([&] {
    const ltm::io::json::Value v = ltm::io::json::ParseFile(path);
    ltm::io::json::Writer w;
    w.BeginArray();
    WriteBack(w, {}, v);
    w.EndArray();
    (void)ltm::io::json::Parse(w.str(), "written back");
  });
  return 0;
}
