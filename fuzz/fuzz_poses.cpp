// Pose text readers on the same bytes: KITTI (io::ReadKittiPoses), TUM (io::ReadTumPoses) and a
// single transform (io::ReadTransform, e.g. KITTI's Tr / relative.txt).
#include "fuzz_common.hpp"
#include "ltmapper/io/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = ltm::fuzz::WriteInput(data, size, ".txt");
  ltm::fuzz::Expect([&] { (void)ltm::io::ReadKittiPoses(path); });
  ltm::fuzz::Expect([&] { (void)ltm::io::ReadTumPoses(path); });
  ltm::fuzz::Expect([&] { (void)ltm::io::ReadTransform(path); });
  return 0;
}
