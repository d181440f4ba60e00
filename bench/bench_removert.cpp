// LT-removert speed and memory: 2 sessions x 500 keyframes of 64-beam scans from the simulator.
// Targets (issue 5): HD removal < 0.05 s per keyframe per core; whole stage < 60 s on 2 cores.
//
//   bench_removert [--benchmark_filter=...]       env: LTM_BENCH_DIR (sim cache, default
//   /tmp/ltm_bench_removert, or /tmp/ltm_bench_removert_SWEEP), LTM_BENCH_THREADS (default 2),
//   LTM_BENCH_KEYFRAMES (default 500), LTM_BENCH_SWEEP (lidar.sweep: instant, the default;
//   distorted: raw sweeps; deskewed: the same saved deskewed, their timing estimated)
//
// CPU seconds come from getrusage (all threads), so "per keyframe per core" = CPU s / keyframes.
// BM_Votes times the hot loop alone (CountVisibility at the removal resolutions over a session
// map built beforehand); BM_Stage2Sessions splits the stage into HD (map + votes), LD and the
// rest (loading the sessions, writing the outputs).
#include "ltmapper/core/core.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"
#include "ltmapper/sim/sim.hpp"

#include <benchmark/benchmark.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

namespace {

namespace fs = std::filesystem;

std::string Env(const char* k, const char* d) {
  const char* v = std::getenv(k);
  return v && *v ? v : d;
}
int Threads() { return std::stoi(Env("LTM_BENCH_THREADS", "2")); }

double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// Simulates the bench scenario once (cached on disk).
const std::string& SimDir() {
  static const std::string dir = [] {
    const std::string sweep = Env("LTM_BENCH_SWEEP", "instant");
    const std::string d =
        Env("LTM_BENCH_DIR", sweep == "instant" ? "/tmp/ltm_bench_removert" : ("/tmp/ltm_bench_removert_" + sweep).c_str());
    const int kf = std::stoi(Env("LTM_BENCH_KEYFRAMES", "500"));
    if (!fs::exists(d + "/truth/session_01/poses_world.txt")) {
      ltm::sim::SimConfig cfg;
      cfg.sessions = 2;
      cfg.keyframes = kf;
      cfg.sweep = sweep;
      std::fprintf(stderr, "simulating 2 sessions x %d keyframes into %s ...\n", kf, d.c_str());
      ltm::sim::Simulate(cfg, d, 0);
    }
    return d;
  }();
  return dir;
}

std::vector<ltm::removert::WorldKeyframe> Keyframes(int s) {
  char name[32];
  std::snprintf(name, sizeof(name), "session_%02d", s);
  const ltm::Session sess = ltm::io::LoadSession(SimDir() + "/sessions/" + name);
  const auto poses = ltm::io::ReadKittiPoses(SimDir() + "/truth/" + name + "/poses_world.txt");
  std::vector<ltm::removert::WorldKeyframe> out = ltm::removert::KeyframesOf(sess);  // with each sweep's motion
  for (std::size_t k = 0; k < poses.size(); ++k) out[k].T_world_sensor = poses[k];
  return out;
}

void PrintSettings(benchmark::State& st) {
  st.SetLabel("threads=" + std::to_string(Threads()) + " hw=" +
              std::to_string(std::thread::hardware_concurrency()));
}

void BM_HdRemovalSession(benchmark::State& st) {
  const auto kfs = Keyframes(0);
  const ltm::removert::RemovertConfig cfg;
  for (auto _ : st) {
    const double c0 = CpuSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    const auto res = ltm::removert::RemoveHd(kfs, cfg, Threads());
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double cpu = CpuSeconds() - c0;
    st.counters["keyframes"] = double(kfs.size());
    st.counters["map_points"] = double(res.stats.map_points);
    st.counters["removed"] = double(res.stats.removed);
    st.counters["wall_s"] = wall;
    st.counters["cpu_s"] = cpu;
    st.counters["s_per_kf_per_core"] = cpu / double(kfs.size());
    st.counters["map_s"] = res.stats.seconds_map;
    st.counters["votes_s"] = res.stats.seconds_votes;
  }
  st.counters["peak_rss_MB"] = double(ltm::PeakRssBytes()) / 1e6;
  PrintSettings(st);
}
BENCHMARK(BM_HdRemovalSession)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

void BM_Votes(benchmark::State& st) {
  const auto kfs = Keyframes(0);
  const ltm::removert::RemovertConfig cfg;
  const ltm::PointCloud map = ltm::removert::BuildSessionMap(kfs, cfg, Threads());
  for (auto _ : st) {
    const double c0 = CpuSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    const auto votes = ltm::removert::CountVisibility(map, kfs, cfg.remove_resolutions_deg, cfg, Threads());
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double cpu = CpuSeconds() - c0;
    benchmark::DoNotOptimize(votes.see.data());
    st.counters["map_points"] = double(map.size());
    st.counters["wall_s"] = wall;
    st.counters["cpu_s"] = cpu;
    st.counters["s_per_kf_per_core"] = cpu / double(kfs.size());
  }
  PrintSettings(st);
}
BENCHMARK(BM_Votes)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

void BM_Stage2Sessions(benchmark::State& st) {
  const std::string d = SimDir();
  const std::string out = d + "/bench_changes";
  ltm::removert::RemovertConfig cfg;
  for (auto _ : st) {
    fs::remove_all(out);
    const double c0 = CpuSeconds();
    const auto rep = ltm::removert::RunRemovertStage(
        cfg, {d + "/sessions/session_00", d + "/sessions/session_01"},
        {d + "/truth/session_00/poses_world.txt", d + "/truth/session_01/poses_world.txt"}, out,
        Threads());
    double hd = 0, ld = 0;
    for (const auto& h : rep.hd) hd += h.seconds_map + h.seconds_votes;
    for (const auto& l : rep.ld) ld += l.seconds;
    st.counters["stage_s"] = rep.seconds;
    st.counters["hd_s"] = hd;
    st.counters["ld_s"] = ld;
    st.counters["rest_s"] = rep.seconds - hd - ld;
    st.counters["cpu_s"] = CpuSeconds() - c0;
    st.counters["peak_rss_MB"] = double(rep.peak_rss_bytes) / 1e6;
  }
  PrintSettings(st);
}
BENCHMARK(BM_Stage2Sessions)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
