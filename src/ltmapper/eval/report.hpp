// ltmapper eval: the Report gathering every result, written as JSON and Markdown.
#pragma once

#include "ltmapper/eval/hd.hpp"
#include "ltmapper/eval/ld.hpp"
#include "ltmapper/eval/livemeta.hpp"
#include "ltmapper/eval/objects.hpp"
#include "ltmapper/eval/restore.hpp"
#include "ltmapper/eval/storage.hpp"
#include "ltmapper/eval/trajectory.hpp"

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ltm::eval {

struct Report {
  std::vector<std::pair<std::string, std::string>> inputs;  // what was scored (name, path)
  std::optional<TrajResult> traj;
  std::optional<HdResult> hd;
  std::optional<LdResult> ld;
  std::optional<RestoreResult> restore;
  std::optional<StorageResult> storage;
  std::optional<ObjectsResult> objects;
  std::optional<LiveMetaResult> livemeta;
};
std::string ToJson(const Report& report);
std::string ToMarkdown(const Report& report);
// Writes either or both (empty path = skip), atomically.
void WriteReport(const Report& report, const std::string& json_path, const std::string& md_path);
// The number at a dotted path ("hd.sa", "traj.sessions.0.ate.trans_m.rmse") of a JSON text;
// nullopt when absent or not a number (null). Malformed JSON throws ltm::Error.
std::optional<double> JsonNumber(const std::string& json_text, const std::string& dotted_path);

}  // namespace ltm::eval
