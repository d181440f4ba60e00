// LT-map benchmarks: composition / rollback per keyframe (target < 5 ms for a 64-beam keyframe of
// ~80k points with a few thousand delta points) and store bytes vs full PCD snapshots.
//   build-*/bench/bench_map [--benchmark_filter=...]
#include "ltmapper/map/detail.hpp"
#include "ltmapper/map/map.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <thread>
#include <unistd.h>

namespace ltm::map {
namespace {

constexpr int kKeyframes = 12;
constexpr int kSessions = 4;
constexpr int kDeltaPerStep = 1500;  // ND and PD each per keyframe and step (3000 delta points)

// A 64-beam-like scan: 64 rings x 1250 azimuths hitting a ground plane / walls 3-60 m away.
PointCloud Scan(std::mt19937& rng) {
  std::normal_distribution<float> noise(0.f, 0.01f);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  PointCloud c;
  for (int r = 0; r < 64; ++r) {
    const double elev = (-24.8 + r * (26.8 / 63.0)) * M_PI / 180.0;
    for (int a = 0; a < 1250; ++a) {
      const double az = a * 2 * M_PI / 1250;
      double range = elev < -0.02 ? 1.73 / std::sin(-elev) : 30.0 + 20.0 * std::sin(3 * az);
      range = std::min(range, 60.0 + 10.0 * std::cos(5 * az));
      c.push_back(float(range * std::cos(elev) * std::cos(az)) + noise(rng),
                  float(range * std::cos(elev) * std::sin(az)) + noise(rng),
                  float(range * std::sin(elev)) + noise(rng), u(rng));
    }
  }
  return c;
}

struct Fixture {
  std::string dir, path;
  std::vector<PointCloud> scans;
  std::size_t snapshot_bytes = 0;
  Fixture() {
    dir = (std::filesystem::temp_directory_path() / ("ltm_bench_map_" + std::to_string(::getpid()))).string();
    std::filesystem::create_directories(dir);
    path = dir + "/bench.ltmap";
    std::mt19937 rng(7);
    MapConfig cfg;
    Store s = Store::Create(path, cfg);
    std::vector<KeyframeInput> base;
    for (int k = 0; k < kKeyframes; ++k) {
      Pose T = Pose::Identity();
      T.translation() = Eigen::Vector3d(10.0 * k, 0, 0);
      base.push_back({k, T, Scan(rng)});
    }
    s.IntegrateBase({"s0"}, base);
    for (int ses = 1; ses < kSessions; ++ses) {
      std::vector<KeyframeDelta> ds;
      for (int k = 0; k < kKeyframes; ++k) {
        const PointCloud cur = s.KeyframeCloud(s.Keyframes()[std::size_t(k)].id, ses - 1);
        KeyframeDelta d;
        d.keyframe = k;
        std::uniform_int_distribution<std::size_t> pick(0, cur.size() - 1);
        for (int i = 0; i < kDeltaPerStep; ++i) {
          const auto& p = cur.points[pick(rng)];
          d.nd_strong.push_back(p.x, p.y, p.z);
        }
        std::uniform_real_distribution<float> u(-20.f, 20.f);
        for (int i = 0; i < kDeltaPerStep; ++i) (i % 2 ? d.pd_weak : d.pd_strong).push_back(u(rng), u(rng), 1.f + u(rng) * 0.05f, 0.5f);
        ds.push_back(std::move(d));
      }
      MapConfig c2 = cfg;
      c2.nd_match_radius_m = 0.002;  // the ND above are exact copies of points
      Store w = Store::Open(path, c2);
      w.IntegrateSession({"s" + std::to_string(ses)}, "s0", ds, {});
    }
    Store r = Store::Open(path);
    for (const auto& ss : r.Sessions()) snapshot_bytes += ss.points * 16 + 200;
  }
  ~Fixture() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
};

Fixture& F() {
  static Fixture f;
  return f;
}

// Restore one keyframe to the central session from the latest (3 inverse deltas): SQLite read,
// checksum, zstd, composition, dequantisation.
void BM_RollbackKeyframeFromStore(benchmark::State& state) {
  Store s = Store::Open(F().path);
  const auto kfs = s.Keyframes();
  std::size_t k = 0, pts = 0;
  for (auto _ : state) {
    const PointCloud c = s.KeyframeCloud(kfs[k++ % kfs.size()].id, 0);
    pts = c.size();
    benchmark::DoNotOptimize(c.points.data());
  }
  state.counters["points"] = double(pts);
}
BENCHMARK(BM_RollbackKeyframeFromStore)->Unit(benchmark::kMillisecond);

// The composition itself on decoded grids: one inverse and one forward delta.
void BM_ComposeOnGrid(benchmark::State& state) {
  std::mt19937 rng(1);
  const PointCloud scan = Scan(rng);
  const detail::QCloud base = detail::Quantize(scan, 0.001, 0.01, PointClass::kStatic, 0, "bench");
  detail::QCloud target;
  detail::KeySet change;
  for (std::size_t i = 0; i < base.size(); ++i) {
    if (i % 50 == 0) change.Insert(detail::Key(base[i]));
    else target.push_back(base[i]);
  }
  for (int i = 0; i < kDeltaPerStep; ++i) target.push_back({i, 20000 + i, 1000, 0, 1, 3, 0});
  const detail::QCloud delta = detail::MakeDelta(base, target, change, {});
  const detail::QCloud latest = detail::ApplyForward(base, delta);
  for (auto _ : state) {
    const detail::QCloud back = detail::ApplyInverse(latest, delta);
    benchmark::DoNotOptimize(back.data());
  }
  state.counters["points"] = double(latest.size());
  state.counters["delta_points"] = double(delta.size());
}
BENCHMARK(BM_ComposeOnGrid)->Unit(benchmark::kMillisecond);

// Checksum + zstd + unshuffle of one 80k-point base blob.
void BM_DecodeBaseBlob(benchmark::State& state) {
  std::mt19937 rng(2);
  const detail::QCloud q = detail::Quantize(Scan(rng), 0.001, 0.01, PointClass::kStatic, 0, "bench");
  const std::string blob = detail::EncodeQ(q, 0.001, 0.01, 3);
  for (auto _ : state) {
    const detail::QCloud d = detail::DecodeQ(blob.data(), blob.size(), "bench");
    benchmark::DoNotOptimize(d.data());
  }
  state.counters["bytes"] = double(blob.size());
}
BENCHMARK(BM_DecodeBaseBlob)->Unit(benchmark::kMillisecond);

// Whole map as of the central session, one thread: time per keyframe = time / keyframes.
void BM_MapAtCentralOneThread(benchmark::State& state) {
  Store s = Store::Open(F().path);
  s.set_threads(1);
  for (auto _ : state) {
    const PointCloud c = s.MapAt(0);
    benchmark::DoNotOptimize(c.points.data());
  }
  state.counters["keyframes"] = kKeyframes;  // time per keyframe = Time / keyframes
}
BENCHMARK(BM_MapAtCentralOneThread)->Unit(benchmark::kMillisecond);

// Store bytes against every session's full map as binary PCD (16 bytes per point).
void BM_StoreSize(benchmark::State& state) {
  Store s = Store::Open(F().path);
  StoreTotals t;
  for (auto _ : state) t = s.Totals();
  state.counters["store_MB"] = double(t.file_bytes) / 1e6;
  state.counters["bases_MB"] = double(t.base_bytes) / 1e6;
  state.counters["deltas_MB"] = double(t.delta_bytes) / 1e6;
  state.counters["snapshots_MB"] = double(F().snapshot_bytes) / 1e6;
  state.counters["ratio_pct"] = 100.0 * double(t.file_bytes) / double(F().snapshot_bytes);
  state.counters["bytes_per_base_point"] = double(t.base_bytes) / double(t.base_points);
}
BENCHMARK(BM_StoreSize)->Iterations(1);

}  // namespace
}  // namespace ltm::map

int main(int argc, char** argv) {
  std::printf("bench_map: %d keyframes of 80000 points (64 x 1250), %d sessions, %d ND + %d PD per keyframe and step, "
              "resolution 1 mm, zstd 3; hardware threads %u\n",
              ltm::map::kKeyframes, ltm::map::kSessions, ltm::map::kDeltaPerStep, ltm::map::kDeltaPerStep,
              std::thread::hardware_concurrency());
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
