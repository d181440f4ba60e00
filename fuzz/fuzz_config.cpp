// YAML configs (io::LoadConfig) on arbitrary bytes: a SlamConfig (whole file and its "slam"
// section) and a RemovertConfig.
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"
#include "ltmapper/slam/slam.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".yaml");
  ltm::fuzz::Expect([&] {
    ltm::slam::SlamConfig cfg;
    ltm::io::LoadConfig(path, cfg);
  });
  ltm::fuzz::Expect([&] {
    ltm::slam::SlamConfig cfg;
    ltm::io::LoadConfig(path, cfg, "slam");
  });
  ltm::fuzz::Expect([&] {
    ltm::removert::RemovertConfig cfg;
    ltm::io::LoadConfig(path, cfg);
  });
  return 0;
}
