#include "ltmapper/core/core.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace ltm {
namespace {

struct DemoConfig {
  double voxel_m = 0.5;
  int beams = 64;
  bool flag = true;
  std::string mode = "cauchy";
  std::vector<double> list = {1.0, 2.0};
  template <class V>
  void Visit(V& v) {
    v("voxel_m", voxel_m, "m", 0.01, 10.0);
    v("lidar.beams", beams, "", 1, 128);
    v("flag", flag);
    v("mode", mode, {"cauchy", "dcs"});
    v("list", list, "m", 0.0, 5.0);
  }
};

TEST(Config, DefaultsValidate) { EXPECT_NO_THROW(ValidateConfig(DemoConfig{})); }

TEST(Config, OutOfRangeNamesKey) {
  DemoConfig c;
  c.beams = 500;
  try {
    ValidateConfig(c, "params.yaml");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("lidar.beams"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("params.yaml"), std::string::npos) << e.what();
  }
}

TEST(Config, BadChoiceAndBadListEntry) {
  DemoConfig c;
  c.mode = "huber";
  EXPECT_THROW(ValidateConfig(c), Error);
  c.mode = "dcs";
  c.list = {1.0, 9.0};
  EXPECT_THROW(ValidateConfig(c), Error);
  c.list.clear();
  EXPECT_THROW(ValidateConfig(c), Error);
}

TEST(Config, PrintsEveryKey) {
  const std::string s = ConfigToString(DemoConfig{});
  for (const char* k : {"voxel_m: 0.5", "lidar.beams: 64", "flag: true", "mode: cauchy", "list: [1, 2]"})
    EXPECT_NE(s.find(k), std::string::npos) << k << " in\n" << s;
}

TEST(PointCloud, SelectKeepsArraysTogether) {
  PointCloud c;
  for (int i = 0; i < 5; ++i) {
    c.push_back(float(i), 0, 0, float(10 * i));
    c.cls.push_back(i % 2 ? PointClass::kHD : PointClass::kStatic);
  }
  const PointCloud s = c.select(std::vector<bool>{true, false, true, false, true});
  ASSERT_EQ(s.size(), 3u);
  ASSERT_EQ(s.cls.size(), 3u);
  EXPECT_FLOAT_EQ(s.points[1].x, 2.f);
  EXPECT_EQ(s.cls[1], PointClass::kStatic);
  EXPECT_TRUE(s.session.empty());
  EXPECT_THROW(c.select(std::vector<bool>{true}), Error);
  const PointCloud t = c.select(std::vector<std::uint32_t>{4, 1});
  EXPECT_FLOAT_EQ(t.points[0].intensity, 40.f);
  EXPECT_EQ(t.cls[1], PointClass::kHD);
}

TEST(PointCloud, AppendDropsArraysPresentOnOneSideOnly) {
  PointCloud a, b;
  a.push_back(0, 0, 0);
  a.cls.push_back(PointClass::kStatic);
  b.push_back(1, 1, 1);
  PointCloud c = a;
  c.append(b);
  EXPECT_EQ(c.size(), 2u);
  EXPECT_TRUE(c.cls.empty());
  PointCloud d = a;
  d.append(a);
  EXPECT_EQ(d.cls.size(), 2u);
  PointCloud e;
  e.append(a);
  EXPECT_EQ(e.cls.size(), 1u);
  // Appending an empty cloud changes nothing: the labels stay (it has no points to lack them).
  PointCloud f = a;
  f.append(PointCloud{});
  EXPECT_EQ(f.cls.size(), 1u);
  EXPECT_NO_THROW(f.CheckConsistent("f"));
  EXPECT_NO_THROW(d.CheckConsistent("d"));
  d.cls.pop_back();
  EXPECT_THROW(d.CheckConsistent("d"), Error);
}

TEST(Session, FindByIndex) {
  Session s;
  for (int i : {0, 2, 5}) {
    Keyframe kf;
    kf.index = i;
    s.keyframes.push_back(kf);
  }
  EXPECT_EQ(s.Find(2), 1);
  EXPECT_EQ(s.Find(3), -1);
  EXPECT_EQ(s.Find(9), -1);
}

TEST(Error, NamesFileAndLine) {
  EXPECT_STREQ(Error("a.g2o", 7, "bad").what(), "a.g2o:7: bad");
  EXPECT_STREQ(Error("a.g2o", 0, "bad").what(), "a.g2o: bad");
}

}  // namespace
}  // namespace ltm

namespace ltm {
namespace {
TEST(Config, SetFieldOverridesByKey) {
  DemoConfig c;
  const auto f = FieldsOf(c);
  SetField(f, "voxel_m=0.25");
  SetField(f, "lidar.beams=32");
  SetField(f, "flag=false");
  SetField(f, "mode=dcs");
  SetField(f, "list=0.5,1.5");
  EXPECT_DOUBLE_EQ(c.voxel_m, 0.25);
  EXPECT_EQ(c.beams, 32);
  EXPECT_FALSE(c.flag);
  EXPECT_EQ(c.mode, "dcs");
  EXPECT_EQ(c.list, (std::vector<double>{0.5, 1.5}));
  SetField(f, "list=[0.25, 2]");  // YAML flow form
  EXPECT_EQ(c.list, (std::vector<double>{0.25, 2.0}));
  EXPECT_THROW(SetField(f, "list=[0.25,x]"), Error);
  EXPECT_THROW(SetField(f, "nokey=1"), Error);
  EXPECT_THROW(SetField(f, "voxel_m=abc"), Error);
  EXPECT_THROW(SetField(f, "voxel_m=1x"), Error);
  EXPECT_THROW(SetField(f, "lidar.beams=1.5"), Error);
  EXPECT_THROW(SetField(f, "flag=yes"), Error);
  EXPECT_THROW(SetField(f, "voxel_m"), Error);
}

// DistinctCounter: within 3 standard errors (3 x 3.3 %) of the true count from 100 to 10^6
// distinct keys, duplicates not counted, and the merge of two overlapping sets estimates their union.
TEST(DistinctCounter, EstimatesDistinctKeysAndUnions) {
  for (std::uint64_t n : {100ULL, 5000ULL, 1000000ULL}) {
    DistinctCounter c;
    for (int pass = 0; pass < 3; ++pass)
      for (std::uint64_t k = 0; k < n; ++k) c.Add(MixHash(k));
    EXPECT_NEAR(c.Estimate(), double(n), 0.1 * double(n)) << n;
  }
  DistinctCounter a, b;
  for (std::uint64_t k = 0; k < 60000; ++k) a.Add(MixHash(k));
  for (std::uint64_t k = 40000; k < 100000; ++k) b.Add(MixHash(k));
  a.Merge(b);
  EXPECT_NEAR(a.Estimate(), 100000.0, 10000.0);
  EXPECT_EQ(DistinctCounter().Estimate(), 0.0);
}

}  // namespace
}  // namespace ltm

namespace ltm {
namespace {
// The pipeline's load and write run on the calling thread in item order, work(i) before write(i),
// at most `window` items loaded and not written; work on later items runs while an item is
// written (write waits for the next item's work: without overlap it never would, and the wait
// times out); an exception from a step reaches the caller after the work in flight ended.
TEST(OrderedPipeline, OrderWindowAndOverlap) {
  for (int threads : {1, 3}) {
    const std::size_t n = 40, window = 4;
    std::vector<std::string> calls;
    std::vector<int> done(n, 0);
    int overlaps = 0;
    std::size_t loaded = 0, written = 0, most_in_flight = 0;
    std::mutex m;
    std::condition_variable cv;
    const std::thread::id caller = std::this_thread::get_id();
    OrderedPipeline(
        n, threads, window,
        [&](std::size_t i) {
          EXPECT_EQ(std::this_thread::get_id(), caller);
          EXPECT_EQ(i, loaded++);
          most_in_flight = std::max(most_in_flight, loaded - written);
        },
        [&](std::size_t i) {
          std::lock_guard<std::mutex> l(m);
          done[i] = 1;
          cv.notify_all();
        },
        [&](std::size_t i) {
          EXPECT_EQ(std::this_thread::get_id(), caller);
          EXPECT_EQ(i, written++);
          std::unique_lock<std::mutex> l(m);
          EXPECT_EQ(done[i], 1);  // its work ended first
          if (threads > 1 && i + 1 < n)
            overlaps += cv.wait_for(l, std::chrono::seconds(10), [&] { return done[i + 1] == 1; });
        });
    EXPECT_EQ(written, n);
    EXPECT_LE(most_in_flight, threads > 1 ? window : 1);
    EXPECT_EQ(overlaps, threads > 1 ? int(n) - 1 : 0);
  }
  std::atomic<int> running{0};
  for (int failing : {0, 1, 2})  // load, work, write
    EXPECT_THROW(OrderedPipeline(
                     20, 2, 4, [&](std::size_t i) { if (failing == 0 && i == 9) throw Error("load failed"); },
                     [&](std::size_t i) {
                       ++running;
                       std::this_thread::sleep_for(std::chrono::milliseconds(5));
                       --running;
                       if (failing == 1 && i == 7) throw Error("work failed");
                     },
                     [&](std::size_t i) {
                       if (failing == 2 && i == 5) throw Error("write failed");
                     }),
                 Error);
  EXPECT_EQ(running.load(), 0);  // no work outlives the call
}
}  // namespace
}  // namespace ltm
