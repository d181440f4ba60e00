#include "ltmapper/pipeline/pipeline.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/eval/eval.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/map/map.hpp"
#include "ltmapper/slam/slam.hpp"

#include "test_util.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <memory>

namespace ltm {
namespace {

TEST(Markdown, TablesHeadingsListsAndEscaping) {
  const std::string html = pipeline::MarkdownToHtml(
      "# Title\n\n| a | b |\n|---|--:|\n| 1 | <2> |\n\n- item `x`\n- two\n\nplain & **bold** <script>x</script>\n");
  test::ExpectContains(html, {"<h2>Title</h2>", "<th>a</th>\n<th align=\"right\">b</th>",
                              "<td>1</td>\n<td align=\"right\">&lt;2&gt;</td>",
                              "<ul>\n<li>item <code>x</code></li>\n<li>two</li>\n</ul>",
                              "<p>plain &amp; <strong>bold</strong>"});
  EXPECT_EQ(html.find("---"), std::string::npos) << html;
  EXPECT_EQ(html.find("<script>"), std::string::npos) << "raw HTML passed through: " << html;
}

TEST(Report, WritesMarkdownAndHtmlWithRelativePictures) {
  test::TempDir dir;
  test::WriteText(dir / "eval/a.md", "## A\n\n| k | v |\n|---|---|\n| x | 1 |\n");
  test::WriteText(dir / "renders/p.png", "not really a png");
  pipeline::WriteReport(dir / "report", "T", {{dir / "eval/a.md", ""}, {dir / "renders/p.png", "cap"}});
  const std::string md = test::ReadText(dir / "report.md");
  const std::string html = test::ReadText(dir / "report.html");
  EXPECT_NE(md.find("# T"), std::string::npos);
  EXPECT_NE(md.find("| x | 1 |"), std::string::npos);
  EXPECT_NE(md.find("![cap](renders/p.png)"), std::string::npos) << md;
  EXPECT_NE(html.find("<img src=\"renders/p.png\""), std::string::npos) << html;
  EXPECT_NE(html.find("<td>x</td>"), std::string::npos);
}

TEST(Report, MissingOrWrongItemIsAnErrorAndWritesNothing) {
  test::TempDir dir;
  EXPECT_THROW(pipeline::WriteReport(dir / "r", "T", {{dir / "missing.md", ""}}), Error);
  test::WriteText(dir / "x.txt", "x");
  EXPECT_THROW(pipeline::WriteReport(dir / "r", "T", {{dir / "x.txt", ""}}), Error);
  EXPECT_FALSE(std::filesystem::exists(dir / "r.md"));
  EXPECT_FALSE(std::filesystem::exists(dir / "r.html"));
}

TEST(Run, NeedsTwoExistingSessions) {
  test::TempDir dir;
  pipeline::RunConfig cfg;
  EXPECT_THROW(pipeline::RunPipeline(cfg, {dir.str()}, dir / "out"), Error);
  try {
    pipeline::RunPipeline(cfg, {dir / "nope_a", dir / "nope_b"}, dir / "out");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nope_a"), std::string::npos) << e.what();
  }
}

TEST(Run, ResumeMarkerHoldsTheStageKey) {
  test::TempDir dir;
  const std::string marker = dir / "STAGE_DONE";
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b\nremovert: x\n"));  // no marker
  pipeline::MarkStageDone(marker, "sessions: a b\nremovert: x\n");
  EXPECT_TRUE(pipeline::StageDone(marker, "sessions: a b\nremovert: x\n"));
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b\nremovert: y\n"));  // a parameter changed
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b c\nremovert: x\n"));
  test::WriteText(marker, "ok\n");  // a marker written before markers held keys: rerun
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b\nremovert: x\n"));
}

TEST(Run, BadStageNameInConfigIsAnError) {
  pipeline::RunConfig cfg;
  cfg.from_stage = "everything";
  EXPECT_THROW(ValidateConfig(cfg), Error);
}

TEST(Cli, RunAndReportUsageErrorsExitNonZero) {
  std::string out;
  EXPECT_NE(test::RunCli("run --out /tmp/x", &out), 0);
  EXPECT_NE(test::RunCli("run --sessions /nonexistent_a /nonexistent_b --out /tmp/ltm_x", &out), 0);
  EXPECT_NE(out.find("nonexistent_a"), std::string::npos) << out;
  EXPECT_NE(test::RunCli("report --out /tmp/ltm_r --item /nonexistent.md", &out), 0);
}

// A read-only OUT is reported at once by every stage command, naming the directory (slam found
// out after 98 s of alignment; `run --from map` printed a raw "filesystem error").
TEST(Cli, ReadOnlyOutIsAnErrorBeforeAnyWork) {
  test::TempDir tmp;
  const std::string ro = tmp / "ro";
  for (const char* d : {"ro", "s0", "s1"}) std::filesystem::create_directories(tmp / d);
  std::filesystem::permissions(ro, std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
  struct Restore {  // so TempDir can remove it
    std::string dir;
    ~Restore() { std::filesystem::permissions(dir, std::filesystem::perms::owner_all); }
  } restore{ro};
  if (access(ro.c_str(), W_OK) == 0) GTEST_SKIP() << "running as root: chmod does not make OUT read-only";
  const std::string sessions = " --sessions " + tmp / "s0" + " " + tmp / "s1";
  test::WriteText(tmp / "p.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  for (const std::string& cmd : std::vector<std::string>{"slam" + sessions + " --out " + ro,
                                                         "run" + sessions + " --out " + ro + " --from map",
                                                         "removert --sessions " + tmp / "s0" + " --poses " + tmp / "p.txt" +
                                                             " --out " + ro}) {
    std::string out;
    EXPECT_NE(test::RunCli(cmd + " --quiet", &out), 0) << cmd;
    EXPECT_NE(out.find(ro + ": output directory is not writable"), std::string::npos) << cmd << "\n" << out;
    EXPECT_EQ(out.find("filesystem error"), std::string::npos) << cmd << "\n" << out;
  }
}

// ------------------------------------------------------------------ reruns into the same OUT
// Small simulated sessions shared by the rerun tests (one sim, one fresh 3-session run).
class Rerun : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = std::make_unique<test::TempDir>();
    // 3 sessions of 45 keyframes that LT-SLAM aligns, with lighter stage params: ~8 s a run.
    test::WriteText(*root_ / "sim.yaml",
                    "seed: 4\nworld: {extent_m: 150.0}\nroute: {sessions: 3, keyframes: 45, keyframe_spacing_m: 4.0}\n"
                    "hd: {cars: 2, pedestrians: 2}\n");
    test::WriteText(*root_ / "slam.yaml", "refine: {rounds: 0}\nsc: {max_loops_per_pair: 6}\n");
    test::WriteText(*root_ / "removert.yaml", "map_voxel_m: 0.3\n");
    // Fewer new-territory keyframes than the defaults: a rerun with it used to read the earlier
    // run's extra new_keyframes/ folders ("no 'new' row for keyframe ...").
    test::WriteText(*root_ / "removert_far.yaml", "map_voxel_m: 0.3\nout: {new_keyframe_dist_m: 40.0}\n");
    std::string out;
    ASSERT_EQ(test::RunCli("sim --quiet --config " + *root_ / "sim.yaml" + " --out " + *root_ / "sim", &out), 0)
        << out;
    fresh3_ = Run({"session_00", "session_01", "session_02"}, *root_ / "fresh3");
  }
  static void TearDownTestSuite() { root_.reset(); }

  static std::string Session(const std::string& name) { return *root_ / ("sim/sessions/" + name); }

  // `ltmapper run` on sim sessions (names under sim/sessions/, or paths) into `out`; returns the output.
  static std::string Run(const std::vector<std::string>& sessions, const std::string& out,
                         const std::string& removert = "removert.yaml") {
    std::string args = "run --quiet --threads 2 --slam-config " + *root_ / "slam.yaml" + " --removert-config " +
                       *root_ / removert + " --out " + out + " --sessions";
    for (const auto& s : sessions) args += " " + (s.find('/') == std::string::npos ? Session(s) : s);
    std::string log;
    EXPECT_EQ(test::RunCli(args, &log), 0) << args << "\n" << log;
    return out;
  }

  // Every file under `dir` (relative path -> bytes), except those holding timings.
  static std::map<std::string, std::string> Files(const std::string& dir) {
    namespace fs = std::filesystem;
    std::map<std::string, std::string> files;
    for (const auto& e : fs::recursive_directory_iterator(dir)) {
      if (!e.is_regular_file()) continue;
      const std::string rel = fs::relative(e.path(), dir).string();
      const std::string name = e.path().filename().string();
      if (name == "report.json" || name == "report.md" || name.rfind("run_report", 0) == 0 ||
          name.rfind("map.ltmap", 0) == 0)
        continue;  // timings (the store's content is checked through live.pcd / meta.pcd / objects)
      files[rel] = test::ReadText(e.path().string());
    }
    return files;
  }

  static void ExpectSameFiles(const std::map<std::string, std::string>& got,
                              const std::map<std::string, std::string>& want) {
    for (const auto& [rel, bytes] : want) {
      const auto it = got.find(rel);
      if (it == got.end()) ADD_FAILURE() << "missing: " << rel;
      else EXPECT_TRUE(it->second == bytes) << "differs from a fresh OUT: " << rel;
    }
    for (const auto& [rel, bytes] : got)
      if (!want.count(rel)) ADD_FAILURE() << "stale file (not in a fresh OUT): " << rel;
  }

  static std::unique_ptr<test::TempDir> root_;
  static std::string fresh3_;
};
std::unique_ptr<test::TempDir> Rerun::root_;
std::string Rerun::fresh3_;

// Issue #16: `run s00 s01` then `run s00 s01 s02` into the same OUT failed in LT-map on the
// first run's new_keyframes/ folders. Now every stage replaces its folder whole: more, fewer or
// other sessions or other parameters into a used OUT give the files of a fresh OUT, byte for byte.
// And with names whose alphabetical order differs from the command line, LT-map took the order
// from a listing of aligned/ and swapped the pairs' changes: the run manifest keeps the
// command-line order, so `base z_drive a_drive` gives the maps and changes of the same sessions
// under sorted names.
TEST_F(Rerun, SameOutWithMoreFewerOrOtherSessionsEqualsFreshOut) {
  namespace fs = std::filesystem;
  const std::string out = *root_ / "reused";
  const auto fresh2 = Files(Run({"session_00", "session_01"}, out, "removert_far.yaml"));
  ASSERT_TRUE(fresh2.count("live.pcd"));
  ASSERT_TRUE(fresh2.count("changes/pair_00_01/keyframes.csv"));
  const auto fresh3 = Files(fresh3_);
  ASSERT_TRUE(fresh3.count("changes/pair_00_02/keyframes.csv")) << "the sim's sessions must all align";
  std::size_t new_kfs_3 = 0, new_kfs_2 = 0;
  for (const auto& [rel, bytes] : fresh3) new_kfs_3 += rel.rfind("changes/pair_00_01/new_keyframes/", 0) == 0;
  for (const auto& [rel, bytes] : fresh2) new_kfs_2 += rel.rfind("changes/pair_00_01/new_keyframes/", 0) == 0;
  ASSERT_GT(new_kfs_3, new_kfs_2) << "the far config must leave fewer new keyframes";
  // More sessions, other LT-removert params, and other session names: the three sessions under
  // names sorted differently from the command line.
  const std::string named = *root_ / "named";
  fs::create_directories(named);
  std::vector<std::string> sessions;
  for (const auto& [name, target] : std::vector<std::pair<std::string, std::string>>{
           {"base", "session_00"}, {"z_drive", "session_01"}, {"a_drive", "session_02"}}) {
    fs::create_directory_symlink(Session(target), named + "/" + name);
    sessions.push_back(named + "/" + name);
  }
  Run(sessions, out);
  const auto manifest = io::ReadRunManifest(io::layout::AlignedDir(out));
  ASSERT_EQ(manifest.sessions.size(), 3u);
  // LT-SLAM measured each query's rotation uncertainty (its loops' residuals), which LD follows;
  // the central has no earlier session to measure against.
  EXPECT_EQ(manifest.sessions[0].rotation_sigma_deg, 0.0);
  for (std::size_t s = 1; s < 3; ++s) {
    EXPECT_GT(manifest.sessions[s].rotation_sigma_deg, 0.0);
    EXPECT_LT(manifest.sessions[s].rotation_sigma_deg, 0.5);
  }
  EXPECT_EQ(manifest.sessions[1].name, "z_drive");
  EXPECT_EQ(manifest.sessions[2].name, "a_drive");
  const auto got = Files(out);
  std::size_t compared = 0;
  for (const auto& [rel, bytes] : fresh3) {  // what does not name a session: byte for byte
    if (rel.rfind("changes/pair_", 0) != 0 && rel != "live.pcd" && rel != "meta.pcd" && rel.rfind("objects/", 0) != 0)
      continue;
    ++compared;
    ASSERT_TRUE(got.count(rel)) << rel;
    EXPECT_TRUE(got.at(rel) == bytes) << "differs from a fresh run under sorted names: " << rel;
  }
  EXPECT_GT(compared, 20u);
  for (const auto& [rel, bytes] : got)  // the rest: the same files, renamed
    if (rel.find("session_0") != std::string::npos) ADD_FAILURE() << "stale file: " << rel;
  EXPECT_EQ(got.size(), fresh3.size());
  std::string log;
  ASSERT_EQ(test::RunCli("map log --store " + out + "/map.ltmap", &log), 0) << log;
  EXPECT_LT(log.find("z_drive"), log.find("a_drive")) << log;
  // Fewer sessions, and fewer new keyframes than the run before left in OUT.
  ExpectSameFiles(Files(Run({"session_00", "session_01"}, out, "removert_far.yaml")), fresh2);
}

// A rebuilt ltmapper never takes an older build's outputs as its own: each stage's key holds the
// hash of the sources it was built from, and a finished run whose markers name other code runs
// every stage again (and writes what a fresh run writes).
TEST_F(Rerun, OutputsOfOtherCodeAreRunAgain) {
  namespace fs = std::filesystem;
  const std::string out = *root_ / "other_code";
  fs::copy(fresh3_, out, fs::copy_options::recursive);
  for (const std::string& m : {out + "/aligned/STAGE_DONE", out + "/changes/STAGE_DONE", out + "/map.ltmap.done"}) {
    std::string key = test::ReadText(m);
    const auto at = key.find("code: ");
    ASSERT_NE(at, std::string::npos) << m << "\n" << key;
    ASSERT_EQ(key.find_first_not_of("0123456789abcdef", at + 6), at + 6 + 64) << key;  // a SHA-256
    key.replace(at + 6, 64, std::string(64, '0'));
    test::WriteText(m, key);
  }
  Run({"session_00", "session_01", "session_02"}, out);
  const std::string report = test::ReadText(out + "/run_report.json");
  EXPECT_EQ(report.find("\"skipped\": true"), std::string::npos) << report;
  ExpectSameFiles(Files(out), Files(fresh3_));
}

// ------------------------------------------------------------------------- lifelong add
// ATE RMSE [m] of each session's world poses in `aligned_dir` against the simulator's truth.
std::map<std::string, double> AteBySession(const std::string& sim_dir, const std::string& aligned_dir) {
  std::vector<std::string> missing;
  const auto traj = eval::LoadSimTrajectories(sim_dir, aligned_dir, &missing);
  EXPECT_TRUE(missing.empty()) << aligned_dir;
  std::map<std::string, double> ate;
  for (const auto& s : eval::EvaluateTrajectories(traj, eval::EvalConfig()).sessions) ate[s.name] = s.ate.trans_m.rmse;
  return ate;
}

PointCloud LiveMap(const std::string& out) {
  return map::Store::Open(out + "/map.ltmap", {}, map::Store::Access::kReadOnly).Live();
}

// Issue #16: `ltmapper add` integrates a third drive into the map of a two-drive run, with the
// map's sessions held fixed, HD removal of the new drive only and one LD pair. Defined
// equivalence with the batch run of the three drives: the added drive placed as well (its ATE
// against the truth within 2 cm of the batch's; the earlier drives' world poses are those of the
// two-drive run, which the batch of three moves by up to 15 cm here, so they are not compared),
// the same class for >= 99 % of the live map's points within one map voxel (both ways), and the
// same store steps.
// Adding it again changes nothing; `run` with the grown list then finds every stage finished.
TEST_F(Rerun, AddingASessionEqualsTheBatchRun) {
  const std::string out = *root_ / "added";
  Run({"session_00", "session_01"}, out);
  const std::string add = "add --quiet --threads 2 --slam-config " + *root_ / "slam.yaml" + " --removert-config " +
                          *root_ / "removert.yaml" + " --map " + out + " " + Session("session_02");
  std::string log;
  ASSERT_EQ(test::RunCli(add, &log), 0) << log;
  EXPECT_NE(log.find("aligned to session_00"), std::string::npos) << log;
  const auto ate_added = AteBySession(*root_ / "sim", io::layout::AlignedDir(out));
  const auto ate_batch = AteBySession(*root_ / "sim", io::layout::AlignedDir(fresh3_));
  ASSERT_TRUE(ate_added.count("session_02") && ate_batch.count("session_02"));
  EXPECT_LE(ate_added.at("session_02"), ate_batch.at("session_02") + 0.02);
  const auto manifest = io::ReadRunManifest(io::layout::AlignedDir(out));
  ASSERT_EQ(manifest.sessions.size(), 3u);
  EXPECT_EQ(manifest.sessions[2].name, "session_02");
  ASSERT_TRUE(std::filesystem::exists(out + "/changes/pair_00_02/keyframes.csv"));
  const PointCloud batch = LiveMap(fresh3_), added = LiveMap(out);
  ASSERT_GT(batch.size(), 1000u);
  constexpr float kMapVoxel = 0.3f;  // removert.yaml's map_voxel_m
  EXPECT_GE(eval::SameClassFraction(batch, added, kMapVoxel), 0.99);
  EXPECT_GE(eval::SameClassFraction(added, batch, kMapVoxel), 0.99);
  std::string mlog;
  ASSERT_EQ(test::RunCli("map log --store " + out + "/map.ltmap", &mlog), 0) << mlog;
  EXPECT_NE(mlog.find("session_02"), std::string::npos) << mlog;

  const auto before = Files(out);
  ASSERT_EQ(test::RunCli(add, &log), 0) << log;
  EXPECT_NE(log.find("Already in the map"), std::string::npos) << log;
  ExpectSameFiles(Files(out), before);
  Run({"session_00", "session_01", "session_02"}, out);
  const std::string report = test::ReadText(out + "/run_report.json");
  EXPECT_EQ(report.find("\"skipped\": false"), std::string::npos) << report;
  ExpectSameFiles(Files(out), before);
}

// Adding to a folder without a finished run, or a drive of another place, is an error naming
// the problem, and the map is left as it was.
TEST_F(Rerun, AddWithoutAMapOrOfAnotherPlaceIsAnErrorAndChangesNothing) {
  std::string log;
  const std::string empty = *root_ / "no_map";
  std::filesystem::create_directories(empty);
  EXPECT_NE(test::RunCli("add --quiet --map " + empty + " " + Session("session_02"), &log), 0);
  EXPECT_NE(log.find("no map here"), std::string::npos) << log;
  // A drive of another simulated world: no loop verifies against any session of the map.
  test::WriteText(*root_ / "other.yaml",
                  "seed: 99\nworld: {extent_m: 150.0}\nroute: {sessions: 1, keyframes: 30, keyframe_spacing_m: 4.0}\n");
  ASSERT_EQ(test::RunCli("sim --quiet --config " + *root_ / "other.yaml" + " --out " + *root_ / "other", &log), 0) << log;
  const std::string elsewhere = *root_ / "elsewhere_drive";  // not a name of the map's sessions
  std::filesystem::create_directory_symlink(*root_ / "other/sessions/session_00", elsewhere);
  const auto before = Files(fresh3_);
  test::WriteText(*root_ / "slam_once.yaml", "refine: {rounds: 0}\nsc: {max_loops_per_pair: 6, retry_rounds: 0}\n");
  EXPECT_NE(test::RunCli("add --quiet --threads 2 --slam-config " + *root_ / "slam_once.yaml" + " --map " + fresh3_ +
                             " " + elsewhere, &log), 0);
  EXPECT_NE(log.find("NOT aligned to any session of the map"), std::string::npos) << log;
  ExpectSameFiles(Files(fresh3_), before);
}

// `run --poses`: LT-removert and LT-map on world poses from elsewhere (here the simulator's
// truth). The sessions are placed exactly as given, and each query's rotation uncertainty, which
// LD's tolerances follow, is measured at those poses as LT-SLAM measures its own (loops verified by
// GICP, their RMS rotation residual): true poses measure the registrations' own error, far below
// LD's prior (pose_sigma_deg, 0.3 deg), which cost 5 points of LD recall on the scenario matrix.
// A rerun finds every stage finished; a wrong pose count names the file.
TEST_F(Rerun, GivenPosesPlaceTheSessionsAndMeasureTheirRotation) {
  const std::string out = *root_ / "given";
  const std::vector<std::string> names = {"session_00", "session_01", "session_02"};
  std::string args = "run --quiet --threads 2 --removert-config " + *root_ / "removert.yaml" + " --out " + out;
  std::string sessions = " --sessions", poses = " --poses";
  for (const auto& n : names) {
    sessions += " " + Session(n);
    poses += " " + *root_ / ("sim/truth/" + n + "/poses_world.txt");
  }
  std::string log;
  ASSERT_EQ(test::RunCli(args + sessions + poses, &log), 0) << log;
  const auto manifest = io::ReadRunManifest(io::layout::AlignedDir(out));
  ASSERT_EQ(manifest.sessions.size(), 3u);
  for (std::size_t s = 0; s < names.size(); ++s) {
    EXPECT_TRUE(manifest.sessions[s].aligned);
    const auto given = io::ReadKittiPoses(*root_ / ("sim/truth/" + names[s] + "/poses_world.txt"));
    const auto placed = io::ReadKittiPoses(io::layout::PosesWorldFile(io::layout::AlignedDir(out), names[s]));
    ASSERT_EQ(placed.size(), given.size());
    for (std::size_t k = 0; k < given.size(); ++k)
      EXPECT_LT((placed[k].matrix() - given[k].matrix()).cwiseAbs().maxCoeff(), 1e-6) << names[s] << " " << k;
  }
  EXPECT_EQ(manifest.sessions[0].rotation_sigma_deg, 0.0);
  for (std::size_t s = 1; s < 3; ++s) {
    EXPECT_GT(manifest.sessions[s].rotation_sigma_deg, 0.0) << names[s];
    EXPECT_LT(manifest.sessions[s].rotation_sigma_deg, 0.1) << names[s];
  }
  EXPECT_NE(test::ReadText(out + "/aligned/loops.csv").find("accepted: measures the given poses"), std::string::npos);
  EXPECT_TRUE(std::filesystem::exists(out + "/changes/pair_00_02/keyframes.csv"));
  ASSERT_EQ(test::RunCli(args + sessions + poses, &log), 0) << log;
  EXPECT_EQ(test::ReadText(out + "/run_report.json").find("\"skipped\": false"), std::string::npos);
  // One pose too few: the file and the counts are named; nothing of the finished run is replaced.
  std::string text = test::ReadText(*root_ / "sim/truth/session_01/poses_world.txt");
  text.erase(text.rfind('\n', text.size() - 2) + 1);
  test::WriteText(*root_ / "short_poses.txt", text);
  const std::string bad_poses = " --poses " + *root_ / "sim/truth/session_00/poses_world.txt" + " " +
                                *root_ / "short_poses.txt" + " " + *root_ / "sim/truth/session_02/poses_world.txt";
  const auto before = Files(out);
  EXPECT_NE(test::RunCli(args + sessions + bad_poses, &log), 0);
  EXPECT_NE(log.find("short_poses.txt"), std::string::npos) << log;
  EXPECT_NE(log.find("44 poses for the 45 keyframes"), std::string::npos) << log;
  ExpectSameFiles(Files(out), before);
  EXPECT_NE(test::RunCli(args + sessions + " --poses " + *root_ / "sim/truth/session_00/poses_world.txt", &log), 0);
  EXPECT_NE(log.find("3 sessions but 1 pose files"), std::string::npos) << log;
  // The measure registers loops with LT-SLAM's config: another config reruns the first stage.
  test::WriteText(*root_ / "slam_given.yaml", "registration:\n  voxel_m: 0.6\n");
  ASSERT_EQ(test::RunCli(args + " --slam-config " + *root_ / "slam_given.yaml" + sessions + poses, &log), 0) << log;
  const std::string report = test::ReadText(out + "/run_report.json");
  const std::size_t slam_at = report.find("\"slam\"");
  ASSERT_NE(slam_at, std::string::npos) << report;
  const std::string ran = "\"skipped\": false";
  EXPECT_EQ(report.compare(report.find("\"skipped\"", slam_at), ran.size(), ran), 0) << report;
}

// The measure of given poses tells their error: the query's true poses turned by a known angle
// about the vertical (around its first keyframe) measure that angle, the true poses measure far
// less (the registrations' own error).
TEST_F(Rerun, GivenPosesMeasureTheirRotationError) {
  const std::vector<std::string> dirs = {Session("session_00"), Session("session_01")};
  const auto truth = [&](const std::string& n) { return *root_ / ("sim/truth/" + n + "/poses_world.txt"); };
  constexpr double kTurnDeg = 0.25;
  std::vector<Pose> turned = io::ReadKittiPoses(truth("session_01"));
  const Pose about = turned.front();
  const Pose turn = about * Pose(Eigen::AngleAxisd(kTurnDeg * M_PI / 180.0, Eigen::Vector3d::UnitZ())) * about.inverse();
  for (Pose& T : turned) T = turn * T;
  io::WriteKittiPoses(*root_ / "turned_poses.txt", turned);
  const auto measure = [&](const std::string& query_poses) {
    slam::GivenPoses g = slam::ReadGivenPoses(dirs, {truth("session_00"), query_poses});
    slam::MeasureGivenPoses(g.sessions, g.placed, slam::SlamConfig(), 2);
    return g.placed.sessions[1].rotation_sigma_deg;
  };
  const double exact = measure(truth("session_01")), off = measure(*root_ / "turned_poses.txt");
  EXPECT_GT(exact, 0.0);
  EXPECT_LT(exact, 0.1);
  EXPECT_GT(off, 0.7 * kTurnDeg) << "exact poses measured " << exact;
  EXPECT_LT(off, 1.3 * kTurnDeg + exact) << "exact poses measured " << exact;
}

// `add --poses`: a drive with world poses of its own joins a map built from given poses the same
// way, placed exactly as given, its rotation measured against the map's sessions.
TEST_F(Rerun, AddWithPosesPlacesTheDriveAsGiven) {
  const std::string out = *root_ / "given_add";
  const auto truth = [&](const std::string& n) { return *root_ / ("sim/truth/" + n + "/poses_world.txt"); };
  std::string log;
  ASSERT_EQ(test::RunCli("run --quiet --threads 2 --removert-config " + *root_ / "removert.yaml" + " --out " + out +
                             " --sessions " + Session("session_00") + " " + Session("session_01") + " --poses " +
                             truth("session_00") + " " + truth("session_01"), &log), 0) << log;
  const std::string add = "add --quiet --threads 2 --removert-config " + *root_ / "removert.yaml" + " --map " + out +
                          " " + Session("session_02");
  EXPECT_NE(test::RunCli(add + " --poses " + truth("session_00") + " " + truth("session_01"), &log), 0);
  EXPECT_NE(log.find("1 sessions but 2 pose files"), std::string::npos) << log;
  ASSERT_EQ(test::RunCli(add + " --poses " + truth("session_02"), &log), 0) << log;
  const auto manifest = io::ReadRunManifest(io::layout::AlignedDir(out));
  ASSERT_EQ(manifest.sessions.size(), 3u);
  EXPECT_GT(manifest.sessions[2].rotation_sigma_deg, 0.0);
  EXPECT_LT(manifest.sessions[2].rotation_sigma_deg, 0.1);
  const auto given = io::ReadKittiPoses(truth("session_02"));
  const auto placed = io::ReadKittiPoses(io::layout::PosesWorldFile(io::layout::AlignedDir(out), "session_02"));
  ASSERT_EQ(placed.size(), given.size());
  for (std::size_t k = 0; k < given.size(); ++k)
    EXPECT_LT((placed[k].matrix() - given[k].matrix()).cwiseAbs().maxCoeff(), 1e-6) << k;
  EXPECT_TRUE(std::filesystem::exists(out + "/changes/pair_00_02/keyframes.csv"));
  EXPECT_NE(test::ReadText(out + "/add_report.md").find("session_00 (given poses)"), std::string::npos);
}

// A stage never replaces a folder that is not an ltmapper output of that stage.
TEST(StagingDir, RefusesForeignFolderAndReplacesItsOwn) {
  test::TempDir tmp;
  test::WriteText(tmp / "mine/a.txt", "user data");
  test::ExpectError([&] { io::StagingDir s(tmp / "mine", "report.json"); }, {tmp / "mine", "refusing"});
  EXPECT_EQ(test::ReadText(tmp / "mine/a.txt"), "user data");
  test::WriteText(tmp / "stage/report.json", "{}");
  test::WriteText(tmp / "stage/old/stale.pcd", "x");
  {
    io::StagingDir s(tmp / "stage", "report.json");
    test::WriteText(s.path() + "/report.json", "new");
    EXPECT_TRUE(std::filesystem::exists(tmp / "stage/old/stale.pcd"));  // not before Publish
    s.Publish();
  }
  EXPECT_FALSE(std::filesystem::exists(tmp / "stage/old"));
  EXPECT_EQ(test::ReadText(tmp / "stage/report.json"), "new");
  { io::StagingDir abandoned(tmp / "stage", "report.json"); }  // not published: nothing changes
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(tmp.str()), {}), 2);
}

TEST(RunManifest, RoundTripsAndNamesTheFileWhenBroken) {
  test::TempDir tmp;
  io::RunManifest m;
  m.sessions = {{"base", "/d/base", true, ""}, {"z: drive", "/d/z", false, "no loop \"found\""},
                {"later", "/d/later", true, "", 0.0625}};
  m.slam_config = "a: 1\nb: 2\n";
  io::WriteRunManifest(tmp.str(), m);
  const auto r = io::ReadRunManifest(tmp.str());
  ASSERT_EQ(r.sessions.size(), 3u);
  EXPECT_EQ(r.sessions[1].name, "z: drive");
  EXPECT_EQ(r.sessions[0].rotation_sigma_deg, 0.0);  // not measured: no key
  EXPECT_DOUBLE_EQ(r.sessions[2].rotation_sigma_deg, 0.0625);
  EXPECT_EQ(r.sessions[1].reason, "no loop \"found\"");
  EXPECT_FALSE(r.sessions[1].aligned);
  EXPECT_EQ(r.slam_config, m.slam_config);
  EXPECT_EQ(r.Aligned().size(), 2u);
  test::WriteText(io::layout::ManifestFile(tmp.str()),
                  "version: 1\nsessions: [{name: a, dir: /a, aligned: true, rotation_sigma_deg: -1}]\n");
  test::ExpectError([&] { io::ReadRunManifest(tmp.str()); }, {"manifest.yaml", "rotation_sigma_deg"});
  test::WriteText(io::layout::ManifestFile(tmp.str()), "version: 1\nsessions: [{name: a}]\n");
  test::ExpectError([&] { io::ReadRunManifest(tmp.str()); }, {"manifest.yaml", "malformed"});
  test::ExpectError([&] { io::ReadRunManifest(tmp / "none"); }, {"manifest.yaml", "not found"});
}

}  // namespace
}  // namespace ltm
