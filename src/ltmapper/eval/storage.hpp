// ltmapper eval: bytes on disk, wall time and peak memory of a stage.
#pragma once

#include "ltmapper/eval/config.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace ltm::eval {

struct StorageItem {
  std::string path;
  std::uint64_t bytes = 0;      // apparent size: sum of regular files' sizes (recursively)
  std::size_t files = 0;
  double ratio_to_first = kNaN; // bytes / bytes of the first item
};
struct CostItem {
  std::string label;            // e.g. the report's path
  double wall_s = kNaN;         // [s]
  double peak_bytes = kNaN;     // [bytes]
};
struct StorageResult {
  std::vector<StorageItem> items;
  std::vector<CostItem> costs;
};
// Throws when `path` does not exist. Symlinks are not followed.
StorageItem MeasureStorage(const std::string& path);
StorageResult EvaluateStorage(const std::vector<std::string>& paths);
// Wall time and peak memory from a stage's report.json: the shallowest numeric field (then
// document order) named wall_time_s / wall_s / seconds_total / elapsed_s / time_s / seconds, and
// peak_rss_bytes / peak_memory_bytes / peak_bytes (bytes) or peak_rss_mb / peak_memory_mb /
// peak_mb (MiB). Absent fields stay NaN; malformed JSON is an error.
CostItem ReadCostReport(const std::string& report_json_path);

}  // namespace ltm::eval
