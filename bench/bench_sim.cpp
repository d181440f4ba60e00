// Simulator throughput: rays per second of the Embree LiDAR and simulation time per keyframe
// on the default city block (params_sim.yaml defaults), for 16 to 128 beams and 1 or all threads.
#include "ltmapper/sim/sim.hpp"

#include <benchmark/benchmark.h>

#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <thread>

namespace {

ltm::sim::Simulator& Sim(int beams, int threads) {
  static std::map<std::pair<int, int>, std::unique_ptr<ltm::sim::Simulator>> cache;
  auto& s = cache[{beams, threads}];
  if (!s) {
    ltm::sim::SimConfig cfg;  // defaults = config/params_sim.yaml
    cfg.beams = beams;
    s = std::make_unique<ltm::sim::Simulator>(cfg, threads);
  }
  return *s;
}

// One keyframe scan (cast + noise + labels), cycling over the keyframes of session 0.
void BM_CastScan(benchmark::State& state) {
  const int beams = int(state.range(0)), threads = int(state.range(1));
  auto& sim = Sim(beams, threads);
  const int n = sim.keyframes(0);
  int k = 0;
  std::size_t points = 0;
  for (auto _ : state) {
    const auto scan = sim.CastScan(0, k);
    points += scan.size();
    benchmark::DoNotOptimize(scan.points.data());
    k = (k + 7) % n;
  }
  const double rays = double(beams) * sim.config().columns;
  state.counters["rays/s"] = benchmark::Counter(rays * double(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["s/keyframe"] = benchmark::Counter(double(state.iterations()),
                                                     benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["points"] = double(points) / double(state.iterations());
  state.counters["threads"] = threads == 0 ? double(std::thread::hardware_concurrency()) : double(threads);
}
BENCHMARK(BM_CastScan)
    ->ArgsProduct({{16, 32, 64, 128}, {0}})
    ->Args({64, 1})
    ->ArgNames({"beams", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Building the world and its Embree scenes.
void BM_BuildWorld(benchmark::State& state) {
  for (auto _ : state) {
    ltm::sim::Simulator sim(ltm::sim::SimConfig{}, 0);
    benchmark::DoNotOptimize(sim.triangles());
    state.counters["triangles"] = double(sim.triangles());
  }
}
BENCHMARK(BM_BuildWorld)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  const ltm::sim::SimConfig cfg;
  benchmark::AddCustomContext("world", std::to_string(int(cfg.extent_m)) + " m, " + cfg.scenario);
  benchmark::AddCustomContext("lidar", std::to_string(cfg.columns) + " columns, fov " + std::to_string(cfg.fov_down_deg) +
                                           ".." + std::to_string(cfg.fov_up_deg) + " deg, max range " +
                                           std::to_string(cfg.max_range_m) + " m");
  benchmark::AddCustomContext("hardware_threads", std::to_string(std::thread::hardware_concurrency()));
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
