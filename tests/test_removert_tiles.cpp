// LT-removert tile by tile (removert/tiles.hpp): on a street longer than the sensor's reach with
// movers crossing tile borders, the tiled HD removal gives the whole-session maps bit for bit,
// for tiles larger and smaller than the sensor range; each tile reads only the keyframes that
// reach it; plans of other keys and bad tiles are refused.
#include "test_removert_scene.hpp"
#include "test_util.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>

namespace ltm {
namespace {

using removert::RemovertConfig;
using removert::WorldKeyframe;

// 70 keyframes 2 m apart along y = 0 (x from 0 to 138 m: three map batches), walls and pillars,
// an oncoming car and pedestrians crossing at tile borders of the small tiles (x = 12, 48, 96).
std::vector<WorldKeyframe> LongStreet() {
  std::vector<test::Box> fixed = {test::MakeBox(-30, 8, 0, 170, 8.3, 4, 1), test::MakeBox(-30, -8.3, 0, 170, -8, 4, 2)};
  for (int x = 5; x < 140; x += 20) fixed.push_back(test::MakeBox(x, 5, 0, x + 0.3, 5.3, 3, 3));
  fixed.push_back(test::MakeBox(58, -6, 0.3, 62, -4, 1.8, 7));  // parked car
  std::vector<WorldKeyframe> kfs;
  for (int k = 0; k < 70; ++k) {
    std::vector<test::Box> boxes = fixed;
    const double cx = 150.0 - 3.5 * k;  // oncoming car in the other lane
    boxes.push_back(test::MakeBox(cx - 2, 2, 0.3, cx + 2, 4, 1.8, 100));
    for (double px : {12.0, 48.0, 96.0}) {  // pedestrians crossing y = 0 (a tile border too)
      const double py = -6.0 + 0.5 * (k % 24);
      boxes.push_back(test::MakeBox(px - 0.25, py - 0.25, 0.05, px + 0.25, py + 0.25, 1.8, 101));
    }
    WorldKeyframe kf;
    kf.index = k;
    kf.T_world_sensor = test::At(2.0 * k, 0.0, 1.8, 0.01 * k);
    kf.cloud = std::make_shared<PointCloud>(test::CastScan(kf.T_world_sensor, boxes, test::Lidar{}));
    kfs.push_back(kf);
  }
  return kfs;
}

// The scanner's range cut to 30 m and the submaps to 25 m: the street is several reaches long.
RemovertConfig ShortRange() {
  RemovertConfig cfg = test::ConfigFor();
  cfg.max_range_m = 30.0;
  cfg.submap_radius_m = 25.0;
  return cfg;
}

bool SameBytes(const PointCloud& a, const PointCloud& b) {
  return a.size() == b.size() && std::memcmp(a.points.data(), b.points.data(), a.size() * sizeof(PointXYZI)) == 0;
}

TEST(RemovertTiles, TiledEqualsWholeSessionBitForBit) {
  const auto kfs = LongStreet();
  const RemovertConfig base = ShortRange();
  const removert::HdResult whole = removert::RemoveHd(kfs, base, 2);
  ASSERT_GT(whole.hd_map.size(), 100u) << "the movers must be removed for the comparison to mean anything";
  // The default (2 x reach = 60 m) and 12.34 m: smaller than the range and not a whole number of
  // voxels (rounded to 12.3 m); the borders cut the pedestrians' paths and the street's axis.
  for (double edge : {0.0, 12.34}) {
    RemovertConfig cfg = base;
    cfg.tiles_edge_m = edge;
    const removert::TilePlan plan = removert::PlanTiles(kfs, removert::WithSensor(cfg, kfs));
    const removert::HdResult tiled = removert::RemoveHdTiled(kfs, cfg, 2);
    std::printf("tiles.edge_m %.2f: %zu tiles, margin %.2f m; static %zu hd %zu (whole: %zu / %zu)\n", plan.EdgeM(),
                plan.tiles.size(), double(plan.margin_voxels) * plan.voxel_m, tiled.static_map.size(),
                tiled.hd_map.size(), whole.static_map.size(), whole.hd_map.size());
    EXPECT_GE(plan.tiles.size(), 4u) << edge;
    EXPECT_TRUE(SameBytes(tiled.static_map, whole.static_map)) << "edge " << edge;
    EXPECT_TRUE(SameBytes(tiled.hd_map, whole.hd_map)) << "edge " << edge;
    EXPECT_EQ(tiled.stats.map_points, whole.stats.map_points) << edge;
    EXPECT_EQ(tiled.stats.candidates, whole.stats.candidates) << edge;
    EXPECT_EQ(tiled.stats.reverted, whole.stats.reverted) << edge;
    EXPECT_EQ(tiled.stats.removed, whole.stats.removed) << edge;
    EXPECT_EQ(tiled.stats.dilated, whole.stats.dilated) << edge;
    EXPECT_EQ(tiled.stats.removed_per_resolution, whole.stats.removed_per_resolution) << edge;
  }
  // Tiles computed in any order (as on a cluster), merged in plan order: the same maps.
  RemovertConfig cfg = removert::WithSensor(base, kfs);
  cfg.tiles_edge_m = 30.0;
  const removert::TilePlan plan = removert::PlanTiles(kfs, cfg);
  std::vector<removert::HdResult> parts(plan.tiles.size());
  for (std::size_t t = plan.tiles.size(); t-- > 0;) parts[t] = removert::RemoveHdTile(plan, t, kfs, cfg, 2);
  const removert::HdResult merged = removert::MergeTiles(plan, parts);
  EXPECT_TRUE(SameBytes(merged.static_map, whole.static_map));
  EXPECT_TRUE(SameBytes(merged.hd_map, whole.hd_map));
  std::swap(parts.front(), parts.back());  // a part given for another tile does not pass unnoticed
  EXPECT_FALSE(SameBytes(removert::MergeTiles(plan, parts).static_map, whole.static_map));
}

// The margin follows the keys it is derived from (TileMarginM): normals of candidates, dilation
// of removed bodies, the groundward cells; the plan rounds it up to whole voxels plus one.
TEST(RemovertTiles, MarginIsDerivedFromTheDecisionsKeys) {
  RemovertConfig cfg;
  // CompleteBodies: (1 + sqrt 2) body lengths and three dilate_body_m on top of the dilation's margin.
  const double bodies = (1.0 + std::sqrt(2.0)) * 5.0 + 3.0 * 0.5;
  EXPECT_DOUBLE_EQ(removert::TileMarginM(cfg), 0.15 + 0.5 + 1.0 + bodies);  // dilate 1.5 voxels + body + normals
  cfg.body_max_m = 0.0;
  EXPECT_DOUBLE_EQ(removert::TileMarginM(cfg), 0.15 + 0.5 + 1.0);
  RemovertConfig no_revert = cfg;
  no_revert.revert = false;
  EXPECT_DOUBLE_EQ(removert::TileMarginM(no_revert), 0.15 + 0.5);
  RemovertConfig no_dilation = cfg;
  no_dilation.dilate_voxels = 0.0;
  EXPECT_DOUBLE_EQ(removert::TileMarginM(no_dilation), 1.0);
  no_dilation.body_max_m = 5.0;  // the bodies need no dilation
  EXPECT_DOUBLE_EQ(removert::TileMarginM(no_dilation), 1.0 + bodies);
  RemovertConfig wide = cfg;
  wide.dilate_voxels = 10.0;  // 1 m: the ground cells (3 x 1 m) reach farthest
  wide.ld_normal_radius_m = 0.3;
  EXPECT_DOUBLE_EQ(removert::TileMarginM(wide), 3.0);
  const removert::TilePlan plan = removert::PlanTiles({}, RemovertConfig{});
  EXPECT_EQ(plan.margin_voxels, 154);  // ceil(15.22 / 0.1) + 1
  EXPECT_EQ(plan.edge_voxels, 2000);  // 2 x max(100, 60) m
  EXPECT_TRUE(plan.tiles.empty());
}

// tiles.max_map_points: the plan counts the map's voxels per cell from the scans and shrinks the
// edge until the largest tile's map (core + margin) is estimated within the bound; the estimate
// is within 10 % of the tiles' real maps, every tile's map stays near the bound, and the merged
// maps are still the whole session's bytes.
TEST(RemovertTiles, MapPointsBoundShrinksTheEdgeKeepingTheBytes) {
  const auto kfs = LongStreet();
  RemovertConfig short_margin = ShortRange();  // the dilation's margin alone: the street is 11 of its tiles long
  short_margin.body_max_m = 0.0;
  RemovertConfig cfg = removert::WithSensor(short_margin, kfs);
  const removert::HdResult whole = removert::RemoveHd(kfs, cfg, 2);
  cfg.tiles_max_map_points = 0;
  const removert::TilePlan unbounded = removert::PlanTiles(kfs, cfg, 2);
  EXPECT_EQ(unbounded.edge_voxels, removert::TileEdgeChoices(cfg).front());
  EXPECT_EQ(unbounded.largest_map_estimate, 0.0);
  cfg.tiles_max_map_points = int(whole.stats.map_points / 5);
  const removert::TilePlan plan = removert::PlanTiles(kfs, cfg, 2);
  EXPECT_LT(plan.edge_voxels, unbounded.edge_voxels);
  EXPECT_LE(plan.largest_map_estimate, double(cfg.tiles_max_map_points));
  std::vector<removert::HdResult> parts;
  double largest = 0.0;  // the real largest map of a tile: its core's points plus the margin's share
  const double grown = double(plan.edge_voxels + 2 * plan.margin_voxels) / double(plan.edge_voxels);
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
    parts.push_back(removert::RemoveHdTile(plan, t, kfs, cfg, 2));
    largest = std::max(largest, double(parts.back().stats.map_points) * grown * grown);
  }
  std::printf("bound %d points: edge %.1f m (unbounded %.1f m), %zu tiles; largest map estimated %.0f, real %.0f\n",
              cfg.tiles_max_map_points, plan.EdgeM(), unbounded.EdgeM(), plan.tiles.size(), plan.largest_map_estimate,
              largest);
  EXPECT_NEAR(plan.largest_map_estimate, largest, 0.1 * largest);
  const removert::HdResult merged = removert::MergeTiles(plan, parts);
  EXPECT_TRUE(SameBytes(merged.static_map, whole.static_map));
  EXPECT_TRUE(SameBytes(merged.hd_map, whole.hd_map));
  // The edges a plan may take: the configured one, then whole multiples of 5 margins below it.
  RemovertConfig defaults;
  const std::vector<std::int64_t> edges = removert::TileEdgeChoices(defaults);
  EXPECT_EQ(edges.front(), 2000);
  EXPECT_EQ(edges[1], 2 * 770);  // margins of 154 voxels
  EXPECT_EQ(edges.back(), 770);
  defaults.body_max_m = 0.0;
  const std::vector<std::int64_t> fine = removert::TileEdgeChoices(defaults);
  EXPECT_EQ(fine[1], 22 * 90);  // margins of 18 voxels
  EXPECT_EQ(fine.back(), 90);
  EXPECT_TRUE(std::is_sorted(edges.rbegin(), edges.rend()));
}

TEST(RemovertTiles, EachTileReadsOnlyTheKeyframesThatReachIt) {
  const auto kfs = LongStreet();
  RemovertConfig cfg = ShortRange();
  cfg.body_max_m = 0.0;  // the dilation's margin alone (1.65 m)
  cfg.tiles_edge_m = 12.0;
  const removert::TilePlan plan = removert::PlanTiles(kfs, cfg);
  ASSERT_FALSE(plan.tiles.empty());
  const double reach = removert::TileReachM(cfg);
  EXPECT_DOUBLE_EQ(reach, 30.0);
  std::size_t most = 0;
  for (const removert::Tile& t : plan.tiles) {
    most = std::max(most, t.keyframes.size());
    EXPECT_TRUE(std::is_sorted(t.keyframes.begin(), t.keyframes.end()));
    // A keyframe of the tile lies within reach + margin + a voxel of the core (xy) ...
    const double x0 = double(t.ix) * plan.EdgeM(), x1 = x0 + plan.EdgeM();
    for (std::size_t k : t.keyframes) {
      const double x = kfs[k].T_world_sensor.translation().x();
      EXPECT_LE(std::max({x0 - x, 0.0, x - x1}), plan.reach_m + double(plan.margin_voxels) * plan.voxel_m);
    }
  }
  // ... so a tile reads about (edge + 2 reach) / 2 m of keyframes: 38 of 70 here.
  EXPECT_LT(most, kfs.size() * 6 / 10);
}

TEST(RemovertTiles, BadTileAndOtherSessionAreErrors) {
  const auto kfs = LongStreet();
  RemovertConfig cfg = ShortRange();
  cfg.tiles_edge_m = 12.0;
  const removert::TilePlan plan = removert::PlanTiles(kfs, cfg);
  test::ExpectError([&] { removert::RemoveHdTile(plan, plan.tiles.size(), kfs, cfg, 1); }, {"tile", "of a plan with"});
  const std::vector<WorldKeyframe> fewer(kfs.begin(), kfs.begin() + 10);
  test::ExpectError([&] { removert::RemoveHdTile(plan, 0, fewer, cfg, 1); }, {"70 keyframes", "has 10"});
  RemovertConfig other = cfg;
  other.tiles_edge_m = 20.0;
  test::ExpectError([&] { removert::RemoveHdTile(plan, 0, kfs, other, 1); }, {"tiles.edge_m"});
  cfg.tiles_edge_m = -1.0;
  EXPECT_THROW(removert::PlanTiles(kfs, cfg), Error);
}

// The jobs from files (what `ltmapper tiles` and the Dask driver run): the merged files are the
// whole-session maps' bytes; a done tile is skipped, a tile without tile.json (killed) is rerun,
// and merging before every tile is done names the missing tile.json.
TEST(RemovertTileJobs, PlanRunMergeEqualsWholeSessionFiles) {
  test::TempDir tmp;
  const std::string session = tmp / "street";
  test::WriteStreetSession(session, 0.0, 30, true);
  RemovertConfig cfg = ShortRange();
  cfg.tiles_edge_m = 20.0;
  const removert::TilePlan plan = removert::WriteTilePlan(tmp / "plan", session, "", cfg);
  ASSERT_GE(plan.tiles.size(), 4u);
  const removert::TilePlanFile read = removert::ReadTilePlan(tmp / "plan");
  EXPECT_EQ(read.plan.tiles.size(), plan.tiles.size());
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) EXPECT_EQ(read.plan.tiles[t].keyframes, plan.tiles[t].keyframes);
  EXPECT_EQ(read.plan.edge_voxels, plan.edge_voxels);
  EXPECT_EQ(read.cfg.tiles_edge_m, 20.0);

  for (std::size_t t = 0; t + 1 < plan.tiles.size(); ++t) EXPECT_TRUE(removert::RunTileJob(tmp / "plan", t, 2));
  const std::string last = removert::TilePartDir(tmp / "plan", plan.tiles.size() - 1);
  test::ExpectError([&] { removert::MergeTileJobs(tmp / "plan", tmp / "out"); }, {last + "/tile.json", "not done"});
  // A killed job: a part written, no tile.json. The rerun writes the tile whole.
  test::WriteText(last + "/static_map.pcd", "half");
  EXPECT_TRUE(removert::RunTileJob(tmp / "plan", plan.tiles.size() - 1, 2));
  EXPECT_FALSE(removert::RunTileJob(tmp / "plan", 0, 2));        // done: skipped
  EXPECT_TRUE(removert::RunTileJob(tmp / "plan", 0, 2, true));   // forced
  const removert::HdStats st = removert::MergeTileJobs(tmp / "plan", tmp / "out");

  const removert::HdResult whole = removert::RemoveHd(removert::LoadWorldKeyframes(session, ""), cfg, 2);
  EXPECT_EQ(st.map_points, whole.stats.map_points);
  io::WritePcd(tmp / "whole_static.pcd", whole.static_map);
  io::WritePcd(tmp / "whole_hd.pcd", whole.hd_map);
  EXPECT_EQ(test::ReadText(tmp / "whole_static.pcd"), test::ReadText(tmp / "out/static_map.pcd"));
  EXPECT_EQ(test::ReadText(tmp / "whole_hd.pcd"), test::ReadText(tmp / "out/hd_map.pcd"));
}

TEST(RemovertTileJobs, BadPlanFilesAreErrorsNamingTheFile) {
  test::TempDir tmp;
  const std::string session = tmp / "street";
  test::WriteStreetSession(session, 0.0, 6, false);
  RemovertConfig cfg = ShortRange();
  const std::string plan_dir = tmp / "plan";
  removert::WriteTilePlan(plan_dir, session, "", cfg);
  test::ExpectError([&] { removert::ReadTilePlan(tmp / "nowhere"); }, {"nowhere/plan.json"});
  test::WriteText(plan_dir + "/plan.json", "{\"format\": \"ltmapper tile plan\", \"tiles\": [");
  test::ExpectError([&] { removert::ReadTilePlan(plan_dir); }, {plan_dir + "/plan.json"});
  test::WriteText(plan_dir + "/plan.json", "{\"format\": \"something else\"}");
  test::ExpectError([&] { removert::ReadTilePlan(plan_dir); }, {plan_dir + "/plan.json", "not a tile plan"});
  // A plan whose tile numbers do not follow from config.yaml's keys.
  removert::WriteTilePlan(plan_dir, session, "", cfg);
  test::WriteText(plan_dir + "/config.yaml", "map_voxel_m: 0.2\n");
  test::ExpectError([&] { removert::ReadTilePlan(plan_dir); }, {plan_dir + "/plan.json", "edge_voxels"});
  test::WriteText(plan_dir + "/config.yaml", "no_such_key: 1\n");
  test::ExpectError([&] { removert::ReadTilePlan(plan_dir); }, {plan_dir + "/config.yaml", "no_such_key"});
  // A plan of the version that listed every keyframe, and keyframe runs out of order.
  removert::WriteTilePlan(plan_dir, session, "", cfg);
  const std::string good = test::ReadText(plan_dir + "/plan.json");
  auto with = [&](const std::string& from, const std::string& to) {
    const std::size_t at = good.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    test::WriteText(plan_dir + "/plan.json", good.substr(0, at) + to + good.substr(at + from.size()));
  };
  with("\"version\": 2", "\"version\": 1");
  test::ExpectError([&] { removert::ReadTilePlan(plan_dir); }, {plan_dir + "/plan.json", "version 2", "plan the tiles again"});
  with("\"keyframe_runs\": [", "\"keyframe_runs\": [[3, 1], ");
  test::ExpectError([&] { removert::ReadTilePlan(plan_dir); }, {plan_dir + "/plan.json", "runs must ascend"});
  // A folder that is no plan is never replaced.
  test::WriteText(tmp / "mine/notes.txt", "keep");
  EXPECT_THROW(removert::WriteTilePlan(tmp / "mine", session, "", cfg), Error);
  EXPECT_TRUE(std::filesystem::exists(tmp / "mine/notes.txt"));
}

// The CLI: plan, merge before the run (exit code 1, the missing tile.json named), run, merge.
TEST(RemovertTileJobs, CliPlanRunMerge) {
  test::TempDir tmp;
  const std::string session = tmp / "street";
  test::WriteStreetSession(session, 0.0, 8, true);
  const std::string sets = " --set sensor.max_range_m=30 --set submap_radius_m=25 --set tiles.edge_m=30";
  std::string out;
  ASSERT_EQ(0, test::RunCli("tiles plan " + session + sets + " --out " + (tmp / "plan"), &out)) << out;
  EXPECT_NE(out.find("tiles: "), std::string::npos) << out;
  EXPECT_NE(0, test::RunCli("tiles merge " + (tmp / "plan") + " --out " + (tmp / "out"), &out));
  EXPECT_NE(out.find("tile_000000/tile.json"), std::string::npos) << out;
  ASSERT_EQ(0, test::RunCli("tiles run " + (tmp / "plan") + " --threads 2", &out)) << out;
  ASSERT_EQ(0, test::RunCli("tiles merge " + (tmp / "plan") + " --out " + (tmp / "out"), &out)) << out;
  ASSERT_EQ(0, test::RunCli("hd " + session + sets + " --out " + (tmp / "whole.pcd"), &out)) << out;
  EXPECT_EQ(test::ReadText(tmp / "whole.pcd"), test::ReadText(tmp / "out/static_map.pcd"));
  EXPECT_NE(0, test::RunCli("tiles run " + (tmp / "plan") + " --tile 99", &out));
  EXPECT_NE(out.find("tile 99 of a plan with"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(removert::TilePartDir(tmp / "plan", 99)));  // refused before any part folder
  // Other poses (--poses, as with LT-SLAM's world poses): the session moved 1.5 m, the same bytes
  // both ways and not the own poses' map; a pose file of another length names the file.
  std::vector<Pose> moved;
  for (const auto& kf : removert::LoadWorldKeyframes(session, "")) moved.push_back(Eigen::Translation3d(1.5, 0, 0) * kf.T_world_sensor);
  io::WriteKittiPoses(tmp / "moved.txt", moved);
  ASSERT_EQ(0, test::RunCli("tiles plan " + session + sets + " --poses " + (tmp / "moved.txt") + " --out " + (tmp / "plan2"), &out)) << out;
  ASSERT_EQ(0, test::RunCli("tiles run " + (tmp / "plan2"), &out)) << out;
  ASSERT_EQ(0, test::RunCli("tiles merge " + (tmp / "plan2") + " --out " + (tmp / "out2"), &out)) << out;
  ASSERT_EQ(0, test::RunCli("hd " + session + sets + " --poses " + (tmp / "moved.txt") + " --out " + (tmp / "moved.pcd"), &out)) << out;
  EXPECT_EQ(test::ReadText(tmp / "moved.pcd"), test::ReadText(tmp / "out2/static_map.pcd"));
  EXPECT_NE(test::ReadText(tmp / "moved.pcd"), test::ReadText(tmp / "whole.pcd"));
  moved.pop_back();
  io::WriteKittiPoses(tmp / "short.txt", moved);
  EXPECT_NE(0, test::RunCli("hd " + session + sets + " --poses " + (tmp / "short.txt") + " --out " + (tmp / "x.pcd"), &out));
  EXPECT_NE(out.find(tmp / "short.txt"), std::string::npos) << out;
}

// Two sessions of a street in tmp/s0 (a parked car at x = 0) and tmp/s1 (none), their world poses
// in tmp/p0.txt and tmp/p1.txt (returned).
std::vector<std::string> TwoStreetSessions(const test::TempDir& tmp) {
  const std::vector<std::vector<Pose>> w = {test::WriteStreetSession(tmp / "s0", -10.0, 12, true),
                                            test::WriteStreetSession(tmp / "s1", -6.0, 12, false)};
  std::vector<std::string> poses;
  for (std::size_t s = 0; s < w.size(); ++s) {
    poses.push_back(tmp / ("p" + std::to_string(s) + ".txt"));
    io::WriteKittiPoses(poses.back(), w[s]);
  }
  return poses;
}

// The stage's keys for them: short range, 15 m HD tiles, only the maps and the pair's clouds.
RemovertConfig PairConfig() {
  RemovertConfig cfg = ShortRange();
  cfg.write_keyframes = false;
  cfg.write_ply = false;
  cfg.tiles_edge_m = 15.0;
  return cfg;
}

// The stage with tiles.stage: true (HD and LD tiles from files, the keyframe folders cut from the
// merged clouds) writes the same files as without: the HD maps, the pair's LD clouds, every
// keyframe's and new keyframe's clouds and keyframes.csv; no work folder is left. Three sessions:
// the third drives further on (new keyframes) and is paired with the central.
TEST(RemovertTileJobs, StageTileByTileWritesTheSameFiles) {
  test::TempDir tmp;
  std::vector<std::string> poses = TwoStreetSessions(tmp);
  poses.push_back(tmp / "p2.txt");
  io::WriteKittiPoses(poses.back(), test::WriteStreetSession(tmp / "s2", 30.0, 12, false));
  RemovertConfig cfg = PairConfig();
  cfg.write_keyframes = true;
  cfg.write_ply = true;            // the keyframes' classes.ply; the whole-map twins are skipped tiled
  cfg.tiles_max_map_points = 1;    // the finest tiles
  // LT-SLAM's rotation measures per session (as `--aligned` reads them from the manifest): each
  // session's HD plan carries the LD tolerance of its own pair, and the pairs' LD plans take them
  // (the plans' configs differed there, and the LD plan refused them as two configs).
  cfg.ld_rotation_sigma_deg = 0.0;  // taken from the measures
  cfg.session_rotation_sigma_deg = {0.0, 0.13, 0.2};
  const std::vector<std::string> sessions = {tmp / "s0", tmp / "s1", tmp / "s2"};
  const removert::StageReport whole = removert::RunRemovertStage(cfg, sessions, poses, tmp / "whole", 2);
  cfg.tiles_stage = true;
  const removert::StageReport tiled = removert::RunRemovertStage(cfg, sessions, poses, tmp / "tiled", 2);
  std::size_t files = 0, keyframe_files = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(tmp / "whole")) {
    const std::string ext = e.path().extension().string(), name = e.path().filename().string();
    if (ext != ".pcd" && ext != ".csv" && name != "classes.ply") continue;
    const std::string rel = std::filesystem::relative(e.path(), tmp / "whole").string();
    EXPECT_EQ(test::ReadText(e.path().string()), test::ReadText(tmp / ("tiled/" + rel))) << rel;
    ++files;
    keyframe_files += rel.find("keyframes/") != std::string::npos ? 1 : 0;
  }
  EXPECT_GE(keyframe_files, 2u * 12u * 7u);  // 12 central keyframes x 6 clouds + classes.ply, 2 pairs
  EXPECT_GE(files, keyframe_files + 2u * 3u + 2u * 8u);  // + 3 x (static, hd) + 2 x (7 clouds + csv)
  EXPECT_FALSE(std::filesystem::exists(tmp / "tiled/.tiles"));
  EXPECT_FALSE(std::filesystem::exists(tmp / "tiled/pair_00_01/.spill"));
  EXPECT_GT(io::ReadPcd(tmp / "tiled/pair_00_01/nd_strong.pcd").size(), 100u);  // the parked car left
  ASSERT_EQ(tiled.new_keyframes.size(), 2u);
  EXPECT_EQ(tiled.new_keyframes, whole.new_keyframes);
  EXPECT_FALSE(tiled.new_keyframes[1].empty()) << "the third session drives past the central's end";
  for (std::size_t p = 0; p < 2; ++p) {
    EXPECT_EQ(tiled.ld[p].nd_strong, whole.ld[p].nd_strong);
    EXPECT_EQ(tiled.ld[p].pd_strong, whole.ld[p].pd_strong);
  }
  EXPECT_EQ(tiled.hd[2].removed, whole.hd[2].removed);
}

// LD from files: the two sessions' HD tiles, then the pair's LD tiles over their parts (in any
// order, one killed), merged: the stage's pair clouds bit for bit; the CLI the same; a query plan
// of another config and a merge before every tile is done are errors naming the file.
TEST(RemovertTileJobs, LdPlanRunMergeEqualsTheStagesPairFiles) {
  test::TempDir tmp;
  const std::vector<std::string> poses = TwoStreetSessions(tmp);
  RemovertConfig cfg = PairConfig();
  cfg.tiles_max_map_points = 1;  // the finest LD tiles: cores meet at x = 0, through the parked car
  removert::RunRemovertStage(cfg, {tmp / "s0", tmp / "s1"}, poses, tmp / "whole", 2);
  for (int s : {0, 1}) {
    const std::string hd = tmp / ("hd" + std::to_string(s));
    const removert::TilePlan plan = removert::WriteTilePlan(hd, tmp / ("s" + std::to_string(s)), poses[std::size_t(s)], cfg);
    for (std::size_t t = 0; t < plan.tiles.size(); ++t) removert::RunTileJob(hd, t, 2);
  }
  const removert::LdTilePlan plan = removert::WriteLdTilePlan(tmp / "ld", tmp / "hd0", tmp / "hd1");
  std::printf("LD tiles: %zu of %.2f m, margin %.2f m, largest window %zu points\n", plan.tiles.size(), plan.EdgeM(),
              double(plan.margin_voxels) * plan.voxel_m, plan.largest_window);
  ASSERT_GE(plan.tiles.size(), 2u);
  EXPECT_TRUE(removert::IsLdTilePlan(tmp / "ld"));
  EXPECT_FALSE(removert::IsLdTilePlan(tmp / "hd0"));
  const removert::LdTilePlanFile read = removert::ReadLdTilePlan(tmp / "ld");
  ASSERT_EQ(read.plan.tiles.size(), plan.tiles.size());
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
    EXPECT_EQ(read.plan.tiles[t].central_voters, plan.tiles[t].central_voters);
    EXPECT_EQ(read.plan.tiles[t].query_voters, plan.tiles[t].query_voters);
  }
  for (std::size_t t = plan.tiles.size(); t-- > 1;) EXPECT_TRUE(removert::RunLdTileJob(tmp / "ld", t, 2));
  const std::string first = removert::TilePartDir(tmp / "ld", 0);
  test::ExpectError([&] { removert::MergeLdTileJobs(tmp / "ld", tmp / "pair"); }, {first + "/tile.json", "not done"});
  test::WriteText(first + "/nd_strong.pcd", "half");  // a killed job: no tile.json, rerun whole
  EXPECT_TRUE(removert::RunLdTileJob(tmp / "ld", 0, 2));
  EXPECT_FALSE(removert::RunLdTileJob(tmp / "ld", 0, 2));  // done: skipped
  const removert::LdStats st = removert::MergeLdTileJobs(tmp / "ld", tmp / "pair");
  EXPECT_GT(st.nd_strong, 100u);  // the parked car left
  {  // A plan whose margin is not what the config and the central's scans give is refused.
    const std::string plan_json = tmp / "ld/plan.json", kept = test::ReadText(plan_json);
    const std::string key = "\"margin_voxels\": ";
    const std::size_t at = kept.find(key);
    ASSERT_NE(at, std::string::npos);
    const std::size_t end = kept.find_first_not_of("0123456789", at + key.size());
    test::WriteText(plan_json, kept.substr(0, at + key.size()) + "1" + kept.substr(end));
    test::ExpectError([&] { removert::RunLdTileJob(tmp / "ld", 0, 2, true); }, {plan_json, "margin_voxels differs"});
    test::WriteText(plan_json, kept);
  }
  std::string out;
  ASSERT_EQ(0, test::RunCli("tiles ld-plan --central " + (tmp / "hd0") + " --query " + (tmp / "hd1") + " --out " +
                                (tmp / "ld_cli"), &out)) << out;
  ASSERT_EQ(0, test::RunCli("tiles run " + (tmp / "ld_cli") + " --threads 2", &out)) << out;
  ASSERT_EQ(0, test::RunCli("tiles merge " + (tmp / "ld_cli") + " --out " + (tmp / "pair_cli"), &out)) << out;
  std::size_t files = 0;
  for (const char* f : {"nd_strong", "nd_weak", "pd_strong", "pd_weak", "pd_unobserved", "nd_residue", "pd_residue"}) {
    const std::string whole = test::ReadText(tmp / ("whole/pair_00_01/" + std::string(f) + ".pcd"));
    EXPECT_EQ(whole, test::ReadText(tmp / ("pair/" + std::string(f) + ".pcd"))) << f;
    EXPECT_EQ(whole, test::ReadText(tmp / ("pair_cli/" + std::string(f) + ".pcd"))) << f;
    ++files;
  }
  EXPECT_EQ(files, 7u);

  // The query's HD tiles not run yet: the error names the first missing tile.json.
  removert::WriteTilePlan(tmp / "hd1", tmp / "s1", poses[1], cfg);
  test::ExpectError([&] { removert::WriteLdTilePlan(tmp / "ld2", tmp / "hd0", tmp / "hd1"); },
                    {tmp / "hd1/parts/tile_000000/tile.json", "not done"});
  RemovertConfig other = cfg;
  other.ld_radius_m = 0.25;
  removert::WriteTilePlan(tmp / "hd1", tmp / "s1", poses[1], other);
  test::ExpectError([&] { removert::WriteLdTilePlan(tmp / "ld2", tmp / "hd0", tmp / "hd1"); },
                    {tmp / "hd1/config.yaml", "one config"});
}

}  // namespace
}  // namespace ltm
