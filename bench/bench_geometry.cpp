// Geometry micro benchmarks: voxel downsampling of 1M points, kd-tree build + 100k radius
// queries, range-image build of a 120k-point scan. Reports points/s (items_per_second).
//   bench_geometry [--benchmark_filter=...]
#include "ltmapper/geometry/geometry.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <thread>

namespace ltm::geometry {
namespace {

// Street-like cloud: ground plane plus walls, 100 m x 100 m, seeded.
PointCloud MakeCloud(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-50.f, 50.f), h(0.f, 10.f), noise(-0.02f, 0.02f);
  PointCloud c;
  c.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    switch (i % 3) {
      case 0: c.push_back(u(rng), u(rng), noise(rng), 1.f); break;            // ground
      case 1: c.push_back(u(rng), 8.f + noise(rng), h(rng), 2.f); break;       // wall
      default: c.push_back(-12.f + noise(rng), u(rng), h(rng), 3.f); break;   // wall
    }
  }
  return c;
}

// A 64 x 1875 spinning scan (120k rays) of a 20 m cylinder with ground, in the sensor frame.
PointCloud MakeScan() {
  PointCloud c;
  const int beams = 64, cols = 1875;
  c.reserve(std::size_t(beams) * cols);
  for (int b = 0; b < beams; ++b) {
    const double el = (2.0 - 26.8 * (b + 0.5) / beams) * M_PI / 180.0;
    for (int k = 0; k < cols; ++k) {
      const double az = 2.0 * M_PI * k / cols;
      double r = 20.0;
      if (el < 0) r = std::min(r, 1.8 / std::sin(-el));  // ground 1.8 m below the sensor
      c.push_back(float(r * std::cos(el) * std::cos(az)), float(r * std::cos(el) * std::sin(az)),
                  float(r * std::sin(el)));
    }
  }
  return c;
}

void BM_VoxelDownsample1M(benchmark::State& state) {
  const PointCloud c = MakeCloud(1000000, 1);
  const int threads = int(state.range(0));
  std::size_t out = 0;
  for (auto _ : state) {
    const PointCloud d = VoxelDownsample(c, 0.2, threads);
    out = d.size();
    benchmark::DoNotOptimize(d.points.data());
  }
  state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(c.size()));
  state.counters["voxels_out"] = double(out);
}
BENCHMARK(BM_VoxelDownsample1M)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_KdTreeBuild(benchmark::State& state) {
  const PointCloud c = MakeCloud(std::size_t(state.range(0)), 2);
  for (auto _ : state) {
    KdTree t(c);
    benchmark::DoNotOptimize(t.size());
  }
  state.SetItemsProcessed(std::int64_t(state.iterations()) * state.range(0));
}
BENCHMARK(BM_KdTreeBuild)->Arg(200000)->Unit(benchmark::kMillisecond);

void BM_KdTreeRadius100k(benchmark::State& state) {
  const KdTree t(MakeCloud(200000, 3));
  const PointCloud q = MakeCloud(100000, 4);
  const float radius = float(state.range(0)) / 10.f;
  std::size_t found = 0;
  for (auto _ : state) {
    found = 0;
    for (const auto& p : q.points) found += t.Radius(p.xyz(), radius).size();
    benchmark::DoNotOptimize(found);
  }
  state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(q.size()));
  state.counters["mean_neighbours"] = double(found) / double(q.size());
}
BENCHMARK(BM_KdTreeRadius100k)->Arg(3)->Arg(10)->Unit(benchmark::kMillisecond);

void BM_KdTreeCountWithin100k(benchmark::State& state) {
  const KdTree t(MakeCloud(200000, 3));
  const PointCloud q = MakeCloud(100000, 4);
  for (auto _ : state) {
    std::size_t n = 0;
    for (const auto& p : q.points) n += t.CountWithin(p.xyz(), 1.0f, 3);
    benchmark::DoNotOptimize(n);
  }
  state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(q.size()));
}
BENCHMARK(BM_KdTreeCountWithin100k)->Unit(benchmark::kMillisecond);

void BM_RangeImageBuild120k(benchmark::State& state) {
  const PointCloud scan = MakeScan();
  RangeImage img(RangeImageConfig{});
  for (auto _ : state) {
    img.Build(scan);
    benchmark::DoNotOptimize(img.data().data());
  }
  state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(scan.size()));
}
BENCHMARK(BM_RangeImageBuild120k)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace ltm::geometry

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  benchmark::AddCustomContext("hardware_threads", std::to_string(std::thread::hardware_concurrency()));
  benchmark::AddCustomContext("settings", "voxel 0.2 m on 1M pts; kd-tree 200k pts, 100k queries; "
                                          "range image 64x900 from a 64x1875 scan");
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
