// PLY reader (io::ReadPly) on arbitrary bytes.
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".ply");
  ltm::fuzz::Expect([&] { ltm::io::ReadPly(path).CheckConsistent("fuzz"); });
  return 0;
}
