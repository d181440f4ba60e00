// KITTI velodyne .bin reader (io::ReadKittiBin) on arbitrary bytes.
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".bin");
  ltm::fuzz::Expect([&] {
    ltm::io::CloudReadStats stats;
    (void)ltm::io::ReadKittiBin(path, &stats);
  });
  return 0;
}
