// ltmapper: one command line with subcommands. Only argument parsing and error reporting live
// here; the subcommands are registered by apps/cmd_*.cpp.
#include "command.hpp"

#include "ltmapper/core/core.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace ltm::app {
namespace {
struct Entry {
  int order;
  std::function<void(CLI::App&)> setup;
};
std::vector<Entry>& Registry() {
  static std::vector<Entry> entries;
  return entries;
}
}  // namespace

CommandRegistrar::CommandRegistrar(int order, std::function<void(CLI::App&)> setup) {
  Registry().push_back({order, std::move(setup)});
}

void AddCommonOptions(CLI::App& cmd, CommonOptions& opts) {
  cmd.add_option("--threads", opts.threads, "Worker threads (0 = all cores)")
      ->check(CLI::Range(0, 1024));
  cmd.add_flag("--quiet", opts.quiet, "Only warnings and errors");
}

}  // namespace ltm::app

int main(int argc, char** argv) {
  CLI::App app{"ltmapper: LiDAR lifelong mapping (LT-SLAM, LT-removert, LT-map)", "ltmapper"};
  app.require_subcommand(1);
  // The code id tells builds apart (what a simulation or a run was made with: scripts/demo.sh).
  app.set_version_flag("--version", std::string("ltmapper 0.1.0 (code ") + ltm::CodeId() + ")");
  auto& entries = ltm::app::Registry();
  std::stable_sort(entries.begin(), entries.end(),
                   [](const auto& a, const auto& b) { return a.order < b.order; });
  for (auto& e : entries) e.setup(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);  // usage errors: message and a non-zero code (0 only for --help)
  } catch (const ltm::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  } catch (const std::exception& e) {
    spdlog::error("unexpected error: {}", e.what());
    return 1;
  }
  return 0;
}
