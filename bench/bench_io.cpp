// Scan reading: io::ReadPcd (our reader for uncompressed binary float x y z intensity, the
// format scans are stored in) against PCL's pcl::io::loadPCDFile into PointXYZI, on a 64 x 1024
// scan (65536 points). Reports points/s (items_per_second).
//   bench_io [--benchmark_filter=...]
#include "ltmapper/io/io.hpp"

#include <benchmark/benchmark.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cmath>
#include <filesystem>
#include <random>
#include <string>
#include <unistd.h>

namespace ltm::io {
namespace {

constexpr int kBeams = 64, kColumns = 1024;

// A scan file written once per process in the temp directory (removed at exit).
const std::string& ScanFile() {
  static const std::string path = [] {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> range(2.f, 80.f), intensity(0.f, 100.f);
    PointCloud c;
    for (int b = 0; b < kBeams; ++b) {
      const float el = float((15.0 - 40.0 * b / (kBeams - 1)) * M_PI / 180.0);
      for (int k = 0; k < kColumns; ++k) {
        const float az = float(2.0 * M_PI * k / kColumns), r = range(rng);
        c.push_back(r * std::cos(el) * std::cos(az), r * std::cos(el) * std::sin(az), r * std::sin(el), intensity(rng));
      }
    }
    const std::string p = (std::filesystem::temp_directory_path() / ("bench_io_" + std::to_string(getpid()) + ".pcd")).string();
    WritePcd(p, c, PcdFormat::kBinary);
    std::atexit([] { std::filesystem::remove(ScanFile()); });
    return p;
  }();
  return path;
}

void BM_ReadPcdOurs(benchmark::State& state) {
  const std::string& path = ScanFile();
  for (auto _ : state) benchmark::DoNotOptimize(ReadPcd(path));
  state.SetItemsProcessed(state.iterations() * kBeams * kColumns);
}
BENCHMARK(BM_ReadPcdOurs)->Unit(benchmark::kMillisecond);

void BM_ReadPcdPcl(benchmark::State& state) {
  const std::string& path = ScanFile();
  for (auto _ : state) {
    pcl::PointCloud<pcl::PointXYZI> c;
    if (pcl::io::loadPCDFile(path, c) != 0) state.SkipWithError("PCL cannot read the scan");
    benchmark::DoNotOptimize(c.data());
  }
  state.SetItemsProcessed(state.iterations() * kBeams * kColumns);
}
BENCHMARK(BM_ReadPcdPcl)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace ltm::io

BENCHMARK_MAIN();
