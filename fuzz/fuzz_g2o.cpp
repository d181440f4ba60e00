// g2o pose graph reader (io::ReadG2o) on arbitrary bytes.
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".g2o");
  ltm::fuzz::Expect([&] { (void)ltm::io::ReadG2o(path); });
  return 0;
}
