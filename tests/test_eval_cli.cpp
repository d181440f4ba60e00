// eval reports (JSON parses back, Markdown), storage/cost, the documented file layouts and the
// `ltmapper eval ...` command line on a tiny hand-built simulator directory.
#include "ltmapper/eval/eval.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

namespace ltm::eval {
namespace {

namespace fs = std::filesystem;
using test::RunCli;
using test::TempDir;

Pose MakePose(double x, double y, double z, double yaw_deg) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// ------------------------------------------------------------------------------- reports
TEST(Report, JsonParsesBackAndNanIsNull) {
  Report rep;
  rep.inputs = {{"output", "a \"quoted\" path"}};
  HdResult hd;
  hd.sa = 0.7;
  hd.da = 0.75;
  hd.aa = std::sqrt(0.7 * 0.75);
  hd.classes = {{"static", 10, 7}, {"hd", 4, 1}};
  rep.hd = hd;
  TrajResult tr;
  tr.sessions.resize(2);
  tr.sessions[1].ate.trans_m.rmse = 0.25;
  rep.traj = tr;
  LdResult ld;  // everything NaN
  rep.ld = ld;
  const std::string js = ToJson(rep);
  EXPECT_NE(js.find("\"sa\": 0.7"), std::string::npos) << js;
  EXPECT_NE(js.find("\"da\": 0.75"), std::string::npos) << js;
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "hd.sa"), 0.7);
  EXPECT_NEAR(*JsonNumber(js, "hd.aa"), std::sqrt(0.525), 1e-9);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "hd.classes.1.total"), 4.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "traj.sessions.1.ate.trans_m.rmse"), 0.25);
  EXPECT_FALSE(JsonNumber(js, "ld.pd.precision").has_value());  // NaN written as null
  EXPECT_NE(js.find("\"precision\": null"), std::string::npos);
  EXPECT_FALSE(JsonNumber(js, "hd.nope").has_value());
  EXPECT_THROW(JsonNumber("{\"a\": [1, 2", "a"), Error);
  EXPECT_THROW(JsonNumber("{\"a\": 1} x", "a"), Error);

  const std::string md = ToMarkdown(rep);
  EXPECT_NE(md.find("## HD removal"), std::string::npos);
  EXPECT_NE(md.find("| 0.7000 | 0.7500 |"), std::string::npos) << md;
  EXPECT_NE(md.find("n/a"), std::string::npos);

  TempDir dir;
  WriteReport(rep, dir / "r.json", dir / "r.md");
  EXPECT_EQ(test::ReadText(dir / "r.json"), js);
  EXPECT_EQ(test::ReadText(dir / "r.md"), md);
}

// ------------------------------------------------------------------------------- storage
TEST(Storage, BytesFilesRatiosAndCostReport) {
  TempDir dir;
  test::WriteText(dir / "tree/a.bin", std::string(1000, 'x'));
  test::WriteText(dir / "tree/sub/b.bin", std::string(24, 'y'));
  test::WriteText(dir / "one.bin", std::string(256, 'z'));
  const auto r = EvaluateStorage({dir / "tree", dir / "one.bin"});
  ASSERT_EQ(r.items.size(), 2u);
  EXPECT_EQ(r.items[0].bytes, 1024u);
  EXPECT_EQ(r.items[0].files, 2u);
  EXPECT_EQ(r.items[1].bytes, 256u);
  EXPECT_DOUBLE_EQ(r.items[1].ratio_to_first, 0.25);
  EXPECT_THROW(MeasureStorage(dir / "missing"), Error);

  test::WriteText(dir / "report.json",
                  R"({"stage": "slam", "sessions": [{"n": 3}], "timing": {"wall_time_s": 12.5},
                      "memory": {"peak_rss_mb": 2.0}})");
  const CostItem c = ReadCostReport(dir / "report.json");
  EXPECT_DOUBLE_EQ(c.wall_s, 12.5);
  EXPECT_DOUBLE_EQ(c.peak_bytes, 2.0 * 1048576.0);
  // As LT-removert writes it: per-pair "seconds" nested before the stage's total.
  test::WriteText(dir / "removert.json",
                  R"({"stage": "removert", "pairs": [{"seconds": 1.5}], "seconds": 7.25, "peak_rss_bytes": 4096})");
  const CostItem r2 = ReadCostReport(dir / "removert.json");
  EXPECT_DOUBLE_EQ(r2.wall_s, 7.25);
  EXPECT_DOUBLE_EQ(r2.peak_bytes, 4096.0);
  test::WriteText(dir / "bad.json", "{\"wall_s\": }");
  EXPECT_THROW(ReadCostReport(dir / "bad.json"), Error);
}

// ------------------------------------------------------------------- tiny simulator layout
// Two sessions of 4 keyframes; each scan has 30 static points (object -1), 6 points of LD
// object 3 ("car", static in this session) and 5 HD points. The estimated world is the central
// session's true frame (origin T0), and the stage outputs are the truth expressed in it.
struct FakeSim {
  std::string sim, aligned, changes;
  Pose T0 = MakePose(40.0, -25.0, 1.0, 30.0);
};

PointCloud Scan(int k) {
  PointCloud c;
  for (int i = 0; i < 30; ++i) {
    c.push_back(float(2 + i % 10), float(-3 + i / 10), float(0.1 * k));
    c.cls.push_back(PointClass::kStatic);
    c.object.push_back(-1);
  }
  for (int i = 0; i < 6; ++i) {
    c.push_back(float(-5 - i), 4.f, 0.5f);
    c.cls.push_back(PointClass::kStatic);
    c.object.push_back(3);
  }
  for (int i = 0; i < 5; ++i) {  // the actor moves: different place in each scan
    c.push_back(float(1 + i), float(6 + 3 * k), 0.8f);
    c.cls.push_back(PointClass::kHD);
    c.object.push_back(100);
  }
  return c;
}

std::string Name(const std::string& d, const std::string& a, const std::string& b = "",
                 const std::string& c = "") {
  fs::path p = fs::path(d) / a;
  if (!b.empty()) p /= b;
  if (!c.empty()) p /= c;
  fs::create_directories(p.parent_path());
  return p.string();
}

FakeSim MakeFakeSim(const TempDir& dir) {
  FakeSim f;
  f.sim = dir / "sim";
  f.aligned = dir / "aligned";
  f.changes = dir / "changes";
  const Pose origins[2] = {f.T0, MakePose(-60.0, 80.0, 0.0, -100.0)};
  for (int s = 0; s < 2; ++s) {
    const std::string name = "session_0" + std::to_string(s);
    std::vector<Pose> world, drifted, est;
    PointCloud static_map, static_world;
    for (int k = 0; k < 4; ++k) {
      const Pose W = origins[s] * MakePose(1.5 * k, 0.3 * k * s, 0.0, 5.0 * k);
      world.push_back(W);
      drifted.push_back(origins[s].inverse() * W * MakePose(0.02 * k, 0, 0, 0.5 * k));
      est.push_back(f.T0.inverse() * W);
      const PointCloud scan = Scan(k);
      io::WritePly(Name(f.sim, "truth", name, "labels/00000" + std::to_string(k) + ".ply"), scan);
      std::vector<bool> is_static(scan.size());
      for (std::size_t i = 0; i < scan.size(); ++i) is_static[i] = scan.cls[i] == PointClass::kStatic;
      static_map.append(geometry::Transform(scan.select(is_static), est.back()));
      static_world.append(geometry::Transform(scan.select(is_static), W));
    }
    static_map.cls.clear(), static_map.object.clear();
    static_world.cls.clear(), static_world.object.clear();
    io::WriteKittiPoses(Name(f.sim, "truth", name, "poses_world.txt"), world);
    io::WriteKittiPoses(Name(f.sim, "truth", name, "origin.txt"), {origins[s]});
    io::WriteKittiPoses(Name(f.sim, "sessions", name, "optimized_poses.txt"), drifted);
    io::WriteKittiPoses(Name(f.aligned, name, "poses_world.txt"), est);
    io::WritePcd(Name(f.changes, name, "static_map.pcd"), static_map);
    io::WritePcd(Name(f.sim, "truth", name, "static_world.pcd"), static_world);
  }
  test::WriteText(f.sim + "/truth/objects.csv",
                  "id,class,present_in,placement,cx,cy,cz\n3,car,\"0;1\",open,0,0,0\n");
  // Change truth (world frame) and the matching prediction (estimated frame).
  const char* kinds[] = {"pd_strong", "pd_weak", "nd_strong", "nd_weak"};
  for (int t = 0; t < 4; ++t) {
    PointCloud w;
    for (int i = 0; i < 5 + t; ++i) w.push_back(float(10 * t + i), 30.f, 0.f);
    w = geometry::Transform(w, f.T0);
    io::WritePcd(Name(f.sim, "truth", "pair_00_01", std::string(kinds[t]) + ".pcd"), w);
    io::WritePcd(Name(f.changes, "pair_session_00_session_01", std::string(kinds[t]) + ".pcd"),
                 geometry::Transform(w, f.T0.inverse()));
  }
  return f;
}

TEST(Layout, FindsFilesByTheDocumentedLayout) {
  TempDir dir;
  const FakeSim f = MakeFakeSim(dir);
  EXPECT_EQ(SimSessionNames(f.sim), (std::vector<std::string>{"session_00", "session_01"}));
  std::vector<std::string> missing;
  const auto traj = LoadSimTrajectories(f.sim, f.aligned, &missing);
  EXPECT_EQ(traj.size(), 2u);
  EXPECT_TRUE(missing.empty());
  EXPECT_EQ(ReadObjectClasses(f.sim + "/truth/objects.csv").at(3), "car");
  EXPECT_TRUE(ReadObjectClasses(f.sim + "/nothing.csv").empty());
  EXPECT_EQ(fs::path(FindPairDir(f.changes, "00_01")).filename(), "pair_session_00_session_01");
  EXPECT_EQ(fs::path(FindPairDir(f.sim + "/truth", "00_01")).filename(), "pair_00_01");
  EXPECT_THROW(FindPairDir(f.changes, "00_02"), Error);
  const Pose A = TruthToEstimateFrame(f.sim, "");
  const Pose B = TruthToEstimateFrame(f.sim, f.aligned);
  EXPECT_LT((A.matrix() - f.T0.inverse().matrix()).norm(), 1e-5);
  EXPECT_LT((B.matrix() - f.T0.inverse().matrix()).norm(), 1e-5);
  // TUM files are read too.
  io::WriteTumPoses(dir / "p.tum", {{0.0, MakePose(1, 2, 3, 4)}, {1.0, MakePose(2, 2, 3, 4)}});
  EXPECT_EQ(ReadPoses(dir / "p.tum").size(), 2u);
  test::WriteText(dir / "bad.txt", "1 2 3\n");
  EXPECT_THROW(ReadPoses(dir / "bad.txt"), Error);
}

// ----------------------------------------------------------------------------------- CLI
TEST(Cli, TruthAsOutputIsPerfectThroughEveryCommand) {
  TempDir dir;
  const FakeSim f = MakeFakeSim(dir);
  std::string out;

  ASSERT_EQ(RunCli("eval traj --sim " + f.sim + " --aligned " + f.aligned + " --json " + (dir / "t.json") +
                       " --md " + (dir / "t.md") + " --quiet",
                   &out),
            0)
      << out;
  std::string js = test::ReadText(dir / "t.json");
  EXPECT_NEAR(*JsonNumber(js, "traj.ate.trans_m.rmse"), 0.0, 1e-5);
  EXPECT_NEAR(*JsonNumber(js, "traj.consistency.trans_m.max"), 0.0, 1e-5);
  EXPECT_NE(out.find("## Trajectories"), std::string::npos) << out;  // Markdown on stdout
  EXPECT_EQ(test::ReadText(dir / "t.md"), out);

  // The drifted input is worse than the truth-as-output.
  ASSERT_EQ(RunCli("eval traj --sim " + f.sim + " --drifted --set traj.align=per_session --json " + (dir / "d.json"), &out), 0) << out;
  EXPECT_GT(*JsonNumber(test::ReadText(dir / "d.json"), "traj.ate.trans_m.max"), 0.01);

  // Explicit files form.
  ASSERT_EQ(RunCli("eval traj --truth-poses " + f.sim + "/truth/session_00/poses_world.txt --est-poses " + f.aligned +
                       "/session_00/poses_world.txt --json " + (dir / "e.json"),
                   &out),
            0)
      << out;
  EXPECT_NEAR(*JsonNumber(test::ReadText(dir / "e.json"), "traj.ate.trans_m.rmse"), 0.0, 1e-5);

  ASSERT_EQ(RunCli("eval hd --sim " + f.sim + " --changes " + f.changes + " --session session_01 --aligned " +
                       f.aligned + " --json " + (dir / "h.json"),
                   &out),
            0)
      << out;
  js = test::ReadText(dir / "h.json");
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "hd.sa"), 1.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "hd.da"), 1.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "hd.static_total"), 4.0 * 36.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "hd.dynamic_total"), 4.0 * 5.0);
  EXPECT_NE(out.find("ld:car"), std::string::npos) << out;
  // Without --aligned the true poses in the central frame are used: the same answer here.
  ASSERT_EQ(RunCli("eval hd --sim " + f.sim + " --changes " + f.changes + " --session session_00 --json " + (dir / "h0.json"), &out), 0) << out;
  EXPECT_DOUBLE_EQ(*JsonNumber(test::ReadText(dir / "h0.json"), "hd.aa"), 1.0);
  {  // The multi-session cleanup: the residues a pair lists for session_01 leave its scored map,
     // unless --single-session.
    const std::string pair = f.changes + "/pair_session_00_session_01";
    const PointCloud map1 = io::ReadPcd(f.changes + "/session_01/static_map.pcd");
    std::vector<std::uint32_t> first(10);
    for (std::uint32_t i = 0; i < 10; ++i) first[i] = i;
    io::WritePcd(pair + "/pd_residue.pcd", map1.select(first));
    io::WritePcd(pair + "/nd_residue.pcd", PointCloud());
    test::WriteText(f.changes + "/report.json",
                    "{\"sessions\": [{\"name\": \"session_00\"}, {\"name\": \"session_01\"}], \"pairs\": "
                    "[{\"central\": 0, \"query\": 1, \"dir\": \"pair_session_00_session_01\"}]}");
    const std::string base = "eval hd --sim " + f.sim + " --changes " + f.changes + " --session session_01 --aligned " + f.aligned;
    ASSERT_EQ(RunCli(base + " --json " + (dir / "hc.json"), &out), 0) << out;
    EXPECT_NE(test::ReadText(dir / "hc.json").find("minus 10 residues"), std::string::npos);
    EXPECT_DOUBLE_EQ(*JsonNumber(test::ReadText(dir / "hc.json"), "hd.output_points"), double(map1.size() - 10));
    EXPECT_LT(*JsonNumber(test::ReadText(dir / "hc.json"), "hd.sa"), 1.0);
    ASSERT_EQ(RunCli(base + " --single-session --json " + (dir / "hs.json"), &out), 0) << out;
    EXPECT_DOUBLE_EQ(*JsonNumber(test::ReadText(dir / "hs.json"), "hd.sa"), 1.0);
    // session_00 is the pair's central: its (empty) nd_residue.pcd takes nothing out.
    ASSERT_EQ(RunCli("eval hd --sim " + f.sim + " --changes " + f.changes + " --session session_00 --json " + (dir / "h0c.json"), &out), 0) << out;
    EXPECT_DOUBLE_EQ(*JsonNumber(test::ReadText(dir / "h0c.json"), "hd.aa"), 1.0);
    for (const char* g : {"/pd_residue.pcd", "/nd_residue.pcd"}) fs::remove(pair + g);
    fs::remove(f.changes + "/report.json");
  }

  ASSERT_EQ(RunCli("eval ld --sim " + f.sim + " --changes " + f.changes + " --pair 00_01 --json " + (dir / "l.json"), &out), 0)
      << out;
  js = test::ReadText(dir / "l.json");
  for (const char* k : {"pd_strong", "pd_weak", "nd_strong", "nd_weak"}) {
    EXPECT_DOUBLE_EQ(*JsonNumber(js, std::string("ld.") + k + ".precision"), 1.0) << k;
    EXPECT_DOUBLE_EQ(*JsonNumber(js, std::string("ld.") + k + ".recall"), 1.0) << k;
  }
  for (const char* k : {"pd_separable", "nd_separable"})  // the sim form splits off the separable truth
    EXPECT_DOUBLE_EQ(*JsonNumber(js, std::string("ld.") + k + ".recall"), 1.0) << k;
  {  // --exact-ray scores against truth/pair_*/exact_ray: an error naming it while it is missing.
    const std::string l = "eval ld --sim " + f.sim + " --changes " + f.changes + " --pair 00_01 --exact-ray --json " +
                          (dir / "le.json");
    EXPECT_EQ(RunCli(l, &out), 1) << out;
    EXPECT_NE(out.find("exact_ray: no exact-ray truth"), std::string::npos) << out;
    const std::string truth = FindPairDir(f.sim + "/truth", "00_01");
    fs::create_directories(io::layout::ExactRayTruthDir(truth));
    for (const char* k : {"pd_strong", "pd_weak", "nd_strong", "nd_weak"})
      fs::copy_file(truth + "/" + k + ".pcd", io::layout::ExactRayTruthDir(truth) + "/" + k + ".pcd");
    ASSERT_EQ(RunCli(l, &out), 0) << out;
    EXPECT_DOUBLE_EQ(*JsonNumber(test::ReadText(dir / "le.json"), "ld.pd.precision"), 1.0);
    EXPECT_NE(test::ReadText(dir / "le.json").find("exact_ray"), std::string::npos);
  }
  // The prediction is in the central frame: claiming it is in the sim world misses everything.
  ASSERT_EQ(RunCli("eval ld --sim " + f.sim + " --changes " + f.changes + " --pair 00_01 --truth-frame world --json " +
                       (dir / "lw.json"),
                   &out),
            0)
      << out;
  EXPECT_DOUBLE_EQ(*JsonNumber(test::ReadText(dir / "lw.json"), "ld.pd.precision"), 0.0);

  ASSERT_EQ(RunCli("eval restore --map-a " + f.changes + "/session_01/static_map.pcd --sim " + f.sim +
                       " --session session_01 --set restore.min_points=5 --json " + (dir / "r.json"),
                   &out),
            0)
      << out;
  js = test::ReadText(dir / "r.json");
  EXPECT_GT(*JsonNumber(js, "restore.np_valid"), 0.0);
  EXPECT_NEAR(*JsonNumber(js, "restore.max"), 0.0, 1e-4);

  ASSERT_EQ(RunCli("eval storage --path " + f.changes + " --path " + f.sim + " --wall-s 3.5 --json " + (dir / "s.json"), &out), 0)
      << out;
  EXPECT_DOUBLE_EQ(*JsonNumber(test::ReadText(dir / "s.json"), "storage.costs.0.wall_s"), 3.5);
}

TEST(Cli, ExitCodesOnMissingFilesAndBadUsage) {
  TempDir dir;
  std::string out;
  EXPECT_EQ(RunCli("eval restore --map-a " + (dir / "missing_a.pcd") + " --map-b " + (dir / "missing_b.pcd"), &out), 1)
      << out;
  EXPECT_EQ(RunCli("eval hd --truth-map " + (dir / "t.ply") + " --output " + (dir / "o.pcd"), &out), 1) << out;
  EXPECT_EQ(RunCli("eval traj --sim " + (dir / "nosim") + " --aligned " + (dir / "a"), &out), 1) << out;
  EXPECT_NE(out.find("nosim"), std::string::npos) << out;
  EXPECT_EQ(RunCli("eval storage --path " + (dir / "nothing"), &out), 1) << out;
  EXPECT_EQ(RunCli("eval ld --sim " + (dir / "nosim") + " --changes " + (dir / "c") + " --pair 00_01", &out), 1) << out;
  // Usage errors are non-zero too, and nothing is written.
  EXPECT_NE(RunCli("eval traj --truth-poses a.txt", &out), 0) << out;
  EXPECT_NE(RunCli("eval hd --output x.pcd", &out), 0) << out;
  EXPECT_NE(RunCli("eval hd --sim s --session session_00 --output x.pcd --single-session", &out), 0) << out;
  EXPECT_NE(out.find("--single-session goes with --changes"), std::string::npos) << out;
  EXPECT_NE(RunCli("eval ld --truth-dir t --pred-dir p --exact-ray", &out), 0) << out;
  EXPECT_NE(out.find("--exact-ray needs --sim"), std::string::npos) << out;
  EXPECT_NE(RunCli("eval restore --map-a a.pcd --set restore.nope=1 --map-b b.pcd", &out), 0) << out;
  EXPECT_NE(RunCli("eval", &out), 0) << out;
  EXPECT_FALSE(fs::exists(dir / "x.json"));
}

}  // namespace
}  // namespace ltm::eval
