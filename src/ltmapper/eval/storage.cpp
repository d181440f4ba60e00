// Storage and cost: bytes of files / directory trees, wall time and peak memory of a stage.
#include "ltmapper/eval/storage.hpp"
#include "ltmapper/io/json.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;

namespace ltm::eval {

StorageItem MeasureStorage(const std::string& path) {
  StorageItem item;
  item.path = path;
  std::error_code ec;
  const auto st = fs::symlink_status(path, ec);
  if (ec || !fs::exists(st)) throw Error(path, 0, "no such file or directory");
  if (fs::is_regular_file(st)) {
    item.bytes = fs::file_size(path);
    item.files = 1;
    return item;
  }
  if (!fs::is_directory(st)) return item;  // a symlink or special file: 0 bytes
  for (auto it = fs::recursive_directory_iterator(path, fs::directory_options::none, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (it->is_symlink()) continue;
    if (it->is_regular_file()) {
      item.bytes += it->file_size();
      ++item.files;
    }
  }
  if (ec) throw Error(path, 0, "cannot list directory: " + ec.message());
  return item;
}

StorageResult EvaluateStorage(const std::vector<std::string>& paths) {
  StorageResult r;
  for (const auto& p : paths) r.items.push_back(MeasureStorage(p));
  if (!r.items.empty() && r.items.front().bytes > 0)
    for (auto& it : r.items) it.ratio_to_first = double(it.bytes) / double(r.items.front().bytes);
  return r;
}

namespace {

// The shallowest numeric field whose key is one of `names` (breadth first, then document
// order), so a stage's total time wins over per-item times nested below it.
const io::json::Value* FindNumber(const io::json::Value& root, const std::vector<std::string>& names,
                              std::size_t* which) {
  std::vector<const io::json::Value*> level = {&root};
  while (!level.empty()) {
    std::vector<const io::json::Value*> next;
    for (const io::json::Value* v : level) {
      if (v->type == io::json::Value::Type::kObject) {
        for (const auto& [k, child] : v->obj) {
          if (child.type == io::json::Value::Type::kNumber)
            for (std::size_t i = 0; i < names.size(); ++i)
              if (k == names[i]) {
                *which = i;
                return &child;
              }
          next.push_back(&child);
        }
      } else if (v->type == io::json::Value::Type::kArray) {
        for (const auto& child : v->arr) next.push_back(&child);
      }
    }
    level = std::move(next);
  }
  return nullptr;
}

}  // namespace

CostItem ReadCostReport(const std::string& path) {
  const io::json::Value doc = io::json::ParseFile(path);
  CostItem c;
  c.label = path;
  std::size_t which = 0;
  if (const auto* t = FindNumber(doc, {"wall_time_s", "wall_s", "seconds_total", "elapsed_s", "time_s", "seconds"}, &which))
    c.wall_s = t->num;
  const std::vector<std::string> mem = {"peak_rss_bytes", "peak_memory_bytes", "peak_bytes",
                                        "peak_rss_mb", "peak_memory_mb", "peak_mb"};
  if (const auto* m = FindNumber(doc, mem, &which)) c.peak_bytes = which < 3 ? m->num : m->num * 1048576.0;
  return c;
}

}  // namespace ltm::eval
