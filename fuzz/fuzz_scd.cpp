// Scan context descriptor reader (io::ReadScd) on arbitrary bytes: the default 20 x 60 and a
// small shape, so that short inputs reach the end of the matrix too.
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".scd");
  ltm::fuzz::Expect([&] { (void)ltm::io::ReadScd(path); });
  ltm::fuzz::Expect([&] { (void)ltm::io::ReadScd(path, 2, 3); });
  return 0;
}
