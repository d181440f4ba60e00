// Subcommand registry for the ltmapper CLI. Each apps/cmd_*.cpp file registers its subcommands
// with a static LTM_COMMAND(...) object, so adding a command touches no shared file.
// Commands only parse arguments, convert types and call module pipelines.
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/io/yaml.hpp"

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

namespace ltm::app {

// `setup` adds one subcommand to `parent` (with its options and callback). `order` sorts the
// help listing.
struct CommandRegistrar {
  CommandRegistrar(int order, std::function<void(CLI::App& parent)> setup);
};

// Shared flags: --threads N (0 = all cores) and --quiet, set up on the subcommand.
struct CommonOptions {
  int threads = 0;
  bool quiet = false;
};
void AddCommonOptions(CLI::App& cmd, CommonOptions& opts);

// A command's params: the defaults, then the params file `path` (when given), then each --set
// KEY=VALUE in order. The caller validates (some apply further options first).
template <class Config>
Config LoadParams(const std::string& path, const std::vector<std::string>& sets) {
  Config cfg;
  if (!path.empty()) io::LoadConfig(path, cfg);
  for (const auto& kv : sets) SetField(FieldsOf(cfg), kv);
  return cfg;
}

}  // namespace ltm::app

#define LTM_CONCAT_INNER(a, b) a##b
#define LTM_CONCAT(a, b) LTM_CONCAT_INNER(a, b)
#define LTM_COMMAND(order, setup) \
  static const ::ltm::app::CommandRegistrar LTM_CONCAT(ltm_command_, __LINE__)(order, setup)
