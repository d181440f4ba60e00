// PCD reader (io::ReadPcd, io::ReadPcdViewpoint) on arbitrary bytes.
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".pcd");
  ltm::fuzz::Expect([&] {
    ltm::io::CloudReadStats stats;
    const auto cloud = ltm::io::ReadPcd(path, &stats);
    cloud.CheckConsistent("fuzz");
  });
  ltm::fuzz::Expect([&] { (void)ltm::io::ReadPcdViewpoint(path); });
  return 0;
}
