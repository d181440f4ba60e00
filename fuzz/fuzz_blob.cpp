// The map store's blob decoder (map::DecodeBlob, and detail::DecodeQ on the raw bytes).
#include "fuzz_common.hpp"
#include "ltmapper/map/detail.hpp"
#include "ltmapper/map/map.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string blob(reinterpret_cast<const char*>(data), size);
  ltm::fuzz::Expect([&] { ltm::map::DecodeBlob(blob, "fuzz").CheckConsistent("fuzz"); });
  ltm::fuzz::Expect([&] {
    double res = 0.0, step = 0.0;
    (void)ltm::map::detail::DecodeQ(data, size, "fuzz", &res, &step);
  });
  return 0;
}
