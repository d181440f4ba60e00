// Changed-object evaluation on hand-built cases with known point IoU, and the sim / map-objects
// file readers on a tiny fake layout.
#include "ltmapper/eval/eval.hpp"
#include "ltmapper/io/io.hpp"

#include "test_util.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include <unistd.h>

namespace fs = std::filesystem;

namespace ltm::eval {
namespace {

// nx x ny grid at z = 0 with 0.1 m spacing at voxel centres (one point per 0.1 m voxel).
PointCloud Grid(int nx, int ny, float x0 = 0.f, float y0 = 0.f) {
  PointCloud c;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j) c.push_back(x0 + 0.05f + 0.1f * float(i), y0 + 0.05f + 0.1f * float(j), 0.05f);
  return c;
}

EvalConfig Cfg() {
  EvalConfig cfg;
  cfg.obj_voxel_m = 0.1;
  cfg.obj_match_dist_m = 0.05;  // below the spacing: only the same grid node matches
  cfg.obj_min_iou = 0.5;
  cfg.obj_min_truth_points = 10;
  return cfg;
}

TEST(Objects, PointIoUHandComputed) {
  const auto cfg = Cfg();
  const PointCloud t = Grid(10, 10);           // 100 points
  EXPECT_DOUBLE_EQ(PointIoU(t, t, cfg), 1.0);
  // Half of the object plus 50 points elsewhere: inter 50, union 100 + 100 - 50 -> 1/3.
  PointCloud c = Grid(5, 10);
  c.append(Grid(5, 10, 20.f, 0.f));
  EXPECT_NEAR(PointIoU(t, c, cfg), 1.0 / 3.0, 1e-12);
  // Half of the object only: inter 50, union 100 -> 0.5.
  EXPECT_NEAR(PointIoU(t, Grid(5, 10), cfg), 0.5, 1e-12);
  // Denser cluster (4 points per voxel) is voxelised first: same IoU as the grid itself.
  PointCloud dense;
  for (const auto& p : t.points)
    for (float d : {-0.02f, 0.02f})
      for (float e : {-0.02f, 0.02f}) dense.push_back(p.x + d, p.y + e, p.z);
  EXPECT_NEAR(PointIoU(t, dense, cfg), 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(PointIoU(t, PointCloud{}, cfg), 0.0);
}

TEST(Objects, EvaluateObjectsFoundFraction) {
  const auto cfg = Cfg();
  std::vector<ObjectTruth> truth(6);
  truth[0] = {"00_01", 7, "car", "open", 0, Grid(10, 10), {}};               // one whole cluster: found
  truth[1] = {"00_01", 8, "tree", "open", 1, Grid(10, 10, 5.f, 0.f), {}};    // glued into a huge cluster: not found
  truth[2] = {"00_02", 9, "car", "open", 2, Grid(10, 10, 10.f, 0.f), {}};    // cluster only in the other pair
  truth[3] = {"00_01", 10, "car", "occluded", 0, Grid(2, 2, 30.f, 0.f), {}}; // 4 points: not scored
  // Removed at an earlier step: clusters of 00_01 are eligible too.
  truth[4] = {"00_02", 11, "car", "open", 0, Grid(10, 10, 10.f, 0.f), {"00_02", "00_01"}};
  truth[5] = {"00_01", 12, "car", "occluded", 0, Grid(10, 10), {}, 5};   // 5 change points: not scored
  std::vector<ObjectCluster> clusters(3);
  clusters[0] = {"00_01", 0, Grid(10, 10), ""};
  clusters[1] = {"00_01", 1, Grid(40, 10, 5.f, 0.f), ""};  // 400 points, 100 of them the tree: IoU 0.25
  clusters[2] = {"00_01", 2, Grid(10, 10, 10.f, 0.f), ""}; // where object 9 is, but wrong pair
  const auto r = EvaluateObjects(truth, clusters, cfg, 2);
  ASSERT_EQ(r.objects.size(), 6u);
  EXPECT_TRUE(r.objects[0].found);
  EXPECT_EQ(r.objects[0].best_cluster, 0);
  EXPECT_NEAR(r.objects[0].best_iou, 1.0, 1e-12);
  EXPECT_FALSE(r.objects[1].found);
  EXPECT_EQ(r.objects[1].best_cluster, 1);
  EXPECT_NEAR(r.objects[1].best_iou, 0.25, 1e-12);
  EXPECT_FALSE(r.objects[2].found);
  EXPECT_EQ(r.objects[2].best_cluster, -1);
  EXPECT_FALSE(r.objects[3].scored);
  EXPECT_TRUE(r.objects[4].found);
  EXPECT_EQ(r.objects[4].best_cluster, 2);
  EXPECT_FALSE(r.objects[5].scored);
  EXPECT_FALSE(r.objects[5].found);
  EXPECT_EQ(r.truth_objects, 4u);
  EXPECT_EQ(r.found, 2u);
  EXPECT_NEAR(r.found_fraction, 0.5, 1e-12);
  EXPECT_EQ(r.clusters, 3u);
  Report rep;
  rep.objects = r;
  EXPECT_NEAR(*JsonNumber(ToJson(rep), "objects.found_fraction"), 0.5, 1e-9);
  EXPECT_NE(ToMarkdown(rep).find("Changed objects"), std::string::npos);
}

// Precision: a cluster with no truth object of its pair at IoU >= min_iou is a false object.
TEST(Objects, PrecisionRecallF1PerPairChangeAndClass) {
  const auto cfg = Cfg();
  std::vector<ObjectTruth> truth(4);
  truth[0] = {"00_01", 7, "car", "open", 0, Grid(10, 10), {}};             // disappeared, found
  truth[1] = {"00_01", 8, "tree", "open", 1, Grid(10, 10, 5.f, 0.f), {}};  // appeared, glued: not found
  truth[2] = {"00_02", 9, "car", "open", 2, Grid(10, 10, 30.f, 0.f), {}};  // appeared, no cluster
  truth[3] = {"00_02", 11, "car", "open", 0, Grid(10, 10, 10.f, 0.f), {"00_02", "00_01"}};  // found at step 1
  std::vector<ObjectCluster> clusters(4);
  clusters[0] = {"00_01", 0, Grid(10, 10), "disappeared"};
  clusters[1] = {"00_01", 1, Grid(40, 10, 5.f, 0.f), "appeared"};   // IoU 0.25 with the tree: false
  clusters[2] = {"00_01", 2, Grid(10, 10, 10.f, 0.f), "disappeared"};
  clusters[3] = {"00_02", 3, Grid(10, 10, 60.f, 0.f), "appeared"};  // nothing there: false
  const auto r = EvaluateObjects(truth, clusters, cfg, 2);
  ASSERT_EQ(r.cluster_scores.size(), 4u);
  EXPECT_TRUE(r.cluster_scores[0].true_object);
  EXPECT_EQ(r.cluster_scores[0].best_truth, 7);
  EXPECT_FALSE(r.cluster_scores[1].true_object);
  EXPECT_NEAR(r.cluster_scores[1].best_iou, 0.25, 1e-12);
  EXPECT_TRUE(r.cluster_scores[2].true_object);  // truth 11 of 00_02 matches clusters of 00_01
  EXPECT_FALSE(r.cluster_scores[3].true_object);
  EXPECT_EQ(r.cluster_scores[3].best_truth, -1);
  EXPECT_EQ(r.all.clusters, 4u);
  EXPECT_EQ(r.all.true_clusters, 2u);
  EXPECT_NEAR(r.all.precision, 0.5, 1e-12);
  EXPECT_NEAR(r.all.recall, 0.5, 1e-12);
  EXPECT_NEAR(r.all.f1, 0.5, 1e-12);
  ASSERT_EQ(r.per_pair.size(), 2u);
  EXPECT_EQ(r.per_pair[0].name, "00_01");
  EXPECT_NEAR(r.per_pair[0].precision, 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(r.per_pair[0].recall, 0.5, 1e-12);
  EXPECT_NEAR(r.per_pair[0].f1, 4.0 / 7.0, 1e-12);
  EXPECT_NEAR(r.per_pair[1].precision, 0.0, 1e-12);
  EXPECT_NEAR(r.per_pair[1].recall, 0.5, 1e-12);
  ASSERT_EQ(r.per_change.size(), 2u);
  EXPECT_EQ(r.per_change[0].name, "appeared");
  EXPECT_NEAR(r.per_change[0].precision, 0.0, 1e-12);
  EXPECT_NEAR(r.per_change[0].recall, 0.0, 1e-12);
  EXPECT_NEAR(r.per_change[0].f1, 0.0, 1e-12);
  EXPECT_NEAR(r.per_change[1].precision, 1.0, 1e-12);
  EXPECT_NEAR(r.per_change[1].recall, 1.0, 1e-12);
  // Per truth class: clusters count for the class of the truth object they overlap most (the one
  // on empty ground counts for none).
  ASSERT_EQ(r.per_class.size(), 2u);
  EXPECT_EQ(r.per_class[0].name, "class car");
  EXPECT_EQ(r.per_class[0].truth_objects, 3u);
  EXPECT_EQ(r.per_class[0].clusters, 2u);
  EXPECT_NEAR(r.per_class[0].precision, 1.0, 1e-12);
  EXPECT_NEAR(r.per_class[0].recall, 2.0 / 3.0, 1e-12);
  EXPECT_EQ(r.per_class[1].name, "class tree");
  EXPECT_NEAR(r.per_class[1].precision, 0.0, 1e-12);
  EXPECT_NEAR(r.per_class[1].recall, 0.0, 1e-12);
  Report rep;
  rep.objects = r;
  const std::string json = ToJson(rep);
  EXPECT_NEAR(*JsonNumber(json, "objects.precision"), 0.5, 1e-9);
  EXPECT_NEAR(*JsonNumber(json, "objects.per_pair.0.precision"), 2.0 / 3.0, 1e-9);
  EXPECT_NEAR(*JsonNumber(json, "objects.per_change.1.recall"), 1.0, 1e-9);
  EXPECT_NEAR(*JsonNumber(json, "objects.per_class.0.recall"), 2.0 / 3.0, 1e-9);
  EXPECT_NE(ToMarkdown(rep).find("| 00_01 | 2 | 1 | 3 | 2 | 0.667 | 0.500 | 0.571 |"), std::string::npos);
}

// Moves: container 10 left one place, 11 is the same container at another (partners); two cars
// came and went. A move is found when both its ends are found by clusters reported as moved,
// linked when those clusters name each other (or a row of each other's track); a cluster reported as
// moved is true when it finds a move's end.
TEST(Objects, MovedFoundLinkedAndPrecision) {
  const auto cfg = Cfg();
  std::vector<ObjectTruth> truth(4);
  truth[0] = {"00_01", 10, "container", "open", 0, Grid(10, 10), {}};
  truth[1] = {"00_01", 11, "container", "open", 1, Grid(10, 10, 20.f, 0.f), {}};
  truth[2] = {"00_01", 7, "car", "open", 0, Grid(10, 10, 40.f, 0.f), {}};
  truth[3] = {"00_01", 8, "car", "open", 1, Grid(10, 10, 60.f, 0.f), {}};
  truth[0].partner = 11, truth[1].partner = 10;
  std::vector<ObjectCluster> clusters(4);
  clusters[0] = {"00_01", 0, Grid(10, 10), "disappeared", true, 1};
  clusters[1] = {"00_01", 1, Grid(10, 10, 20.f, 0.f), "appeared", true, 0};
  clusters[2] = {"00_01", 2, Grid(10, 10, 40.f, 0.f), "disappeared", true, 3};  // two cars: not a move
  clusters[3] = {"00_01", 3, Grid(10, 10, 60.f, 0.f), "appeared", true, 2};
  auto r = EvaluateObjects(truth, clusters, cfg, 2);
  ASSERT_EQ(r.moved.size(), 2u);  // all, 00_01
  const MovedPrf& m = r.moved[0];
  EXPECT_EQ(m.name, "all");
  EXPECT_EQ(m.truth_moves, 1u);
  EXPECT_EQ(m.found, 1u);
  EXPECT_EQ(m.linked, 1u);
  EXPECT_EQ(m.reported, 4u);
  EXPECT_EQ(m.true_reported, 2u);
  EXPECT_NEAR(m.precision, 0.5, 1e-12);
  EXPECT_NEAR(m.recall, 1.0, 1e-12);
  EXPECT_EQ(r.moved[1].name, "00_01");
  EXPECT_EQ(r.moved[1].found, 1u);
  Report rep;
  rep.objects = r;
  EXPECT_NEAR(*JsonNumber(ToJson(rep), "objects.moved.0.precision"), 0.5, 1e-9);
  const std::string md = ToMarkdown(rep);
  EXPECT_NE(md.find("| all | 1 | 1 | 1 | 4 | 2 | 0.500 | 1.000 |"), std::string::npos);
  // Every reported object with its verdict: the container's end true, the car "moved" too.
  EXPECT_NE(md.find("| 00_01 | 0 | moved | 1 | - | 100 | 10 (container) | 1.000 | yes |"), std::string::npos) << md;
  EXPECT_NE(md.find("| 00_01 | 2 | moved | 3 | - | 100 | 7 (car) | 1.000 | yes |"), std::string::npos) << md;
  // A later step's view of the container's new place (cluster 1, track 4) inherited the partner of
  // step 1's view (cluster 4, the same track): linked through the track; through another track, not.
  clusters.push_back({"00_01", 4, Grid(10, 10, 20.f, 0.f), "appeared", true, 0, 4});
  clusters[1].track = 4, clusters[0].partner = 4;
  r = EvaluateObjects(truth, clusters, cfg, 2);
  EXPECT_EQ(r.moved[0].linked, 1u);
  clusters[4].track = 5;
  r = EvaluateObjects(truth, clusters, cfg, 2);
  EXPECT_EQ(r.moved[0].linked, 0u);
  clusters.pop_back();
  clusters[1].track = -1, clusters[0].partner = 1;
  // Both ends reported as moved, each linked to a car: found, not linked.
  clusters[0].partner = 3, clusters[3].partner = 0, clusters[1].partner = 2, clusters[2].partner = 1;
  r = EvaluateObjects(truth, clusters, cfg, 2);
  EXPECT_EQ(r.moved[0].found, 1u);
  EXPECT_EQ(r.moved[0].linked, 0u);
  // The container's new place reported as appeared: the move is not found.
  clusters[1].moved = false, clusters[1].partner = -1;
  r = EvaluateObjects(truth, clusters, cfg, 2);
  EXPECT_EQ(r.moved[0].found, 0u);
  EXPECT_NEAR(r.moved[0].recall, 0.0, 1e-12);
}

// Identity across steps: truth car 7 gone since session 0 is found by the clusters of steps 1
// and 2; both in one track is right, car 8 of step 2 in that track too is wrong.
TEST(Objects, IdentityAcrossSteps) {
  const auto cfg = Cfg();
  std::vector<ObjectTruth> truth(3);
  truth[0] = {"00_01", 7, "car", "open", 0, Grid(10, 10), {}};
  truth[1] = {"00_02", 7, "car", "open", 0, Grid(10, 10), {}};
  truth[2] = {"00_02", 8, "car", "open", 2, Grid(10, 10, 40.f, 0.f), {}};
  std::vector<ObjectCluster> clusters(3);
  clusters[0] = {"00_01", 0, Grid(10, 10), "disappeared", false, -1, 0};
  clusters[1] = {"00_02", 1, Grid(10, 10), "disappeared", false, -1, 0};
  clusters[2] = {"00_02", 2, Grid(10, 10, 40.f, 0.f), "appeared", false, -1, 2};
  auto r = EvaluateObjects(truth, clusters, cfg, 2);
  EXPECT_EQ(r.identity.same, 1u);
  EXPECT_EQ(r.identity.same_tracked, 1u);
  EXPECT_EQ(r.identity.tracked, 1u);
  EXPECT_EQ(r.identity.tracked_wrong, 0u);
  clusters[1].track = 1, clusters[2].track = 0;  // step 2's rows swapped: car 8 in car 7's track
  r = EvaluateObjects(truth, clusters, cfg, 2);
  EXPECT_EQ(r.identity.same_tracked, 0u);
  EXPECT_EQ(r.identity.tracked, 1u);
  EXPECT_EQ(r.identity.tracked_wrong, 1u);
  Report rep;
  rep.objects = r;
  EXPECT_NEAR(*JsonNumber(ToJson(rep), "objects.identity.tracked_wrong"), 1.0, 1e-9);
}

void WriteText(const std::string& path, const std::string& text) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path) << text;
}

TEST(Objects, SimTruthAndClusterFiles) {
  const fs::path dir = fs::temp_directory_path() / ("ltm_eval_objects_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string t = (dir / "sim" / "truth").string();
  WriteText(t + "/objects.csv",
            "id,class,present_in,placement,centroid_x,partner\n"
            "3,car,0,open,0,5\n"     // only in 00: changed for 00_01; moved to 5
            "4,fence,0;1,open,0,-1\n"  // in both: not changed
            "5,car,1,open,0,3\n");   // only in 01: changed
  // One scan per session; session 01's true pose is shifted by +100 m in x.
  for (int s = 0; s < 2; ++s) {
    const std::string sd = t + "/session_0" + std::to_string(s);
    WriteText(sd + "/poses_world.txt", s == 0 ? "1 0 0 0 0 1 0 0 0 0 1 0\n" : "1 0 0 100 0 1 0 0 0 0 1 0\n");
    WriteText(sd + "/origin.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
    PointCloud scan = Grid(10, 10);
    scan.append(Grid(10, 10, 5.f, 0.f));
    scan.append(Grid(3, 3, 9.f, 0.f));  // HD actor sharing the id of a changed object
    scan.cls.assign(scan.size(), PointClass::kStatic);
    scan.object.assign(scan.size(), -1);
    scan.session.assign(scan.size(), std::uint16_t(s));
    for (std::size_t i = 0; i < 100; ++i) scan.object[i] = s == 0 ? 3 : 5;
    for (std::size_t i = 100; i < 200; ++i) scan.object[i] = 4;
    for (std::size_t i = 200; i < scan.size(); ++i) scan.cls[i] = PointClass::kHD, scan.object[i] = s == 0 ? 3 : 5;
    fs::create_directories(sd + "/labels");
    io::WritePly(sd + "/labels/000000.ply", scan);
  }
  // The pair's change truth: object 3 seen through by the later session on 30 points, 10 it never
  // saw (observed share 0.75); object 5 mostly in space the earlier session never observed (PD
  // strong 30, weak 10: 0.25), a coverage difference by the rule.
  PointCloud ch;
  for (int k = 0; k < 80; ++k) {
    ch.push_back(float(k), 0.f, 0.f);
    ch.object.push_back(k < 40 ? 3 : 5);
    const int j = k % 40;
    ch.cls.push_back(k < 40 ? (j < 30 ? PointClass::kNDStrong : PointClass::kNDWeak)
                            : (j < 30 ? PointClass::kPDStrong : PointClass::kPDWeak));
  }
  ch.session.assign(ch.size(), 0);
  fs::create_directories(t + "/pair_00_01");
  io::WritePly(t + "/pair_00_01/changes.ply", ch);
  const auto truth = LoadSimObjectTruth((dir / "sim").string(), "00_01", GlobalTruthMapping(Pose::Identity(), "identity"), Cfg());
  ASSERT_EQ(truth.size(), 2u);
  EXPECT_EQ(truth[0].change_points, 30);  // strong ND only: what clustering can see
  EXPECT_NEAR(truth[0].observed_share, 0.75, 1e-12);
  EXPECT_EQ(truth[1].change_points, 40);
  EXPECT_NEAR(truth[1].observed_share, 0.25, 1e-12);
  EXPECT_EQ(truth[0].id, 3);
  EXPECT_EQ(truth[0].partner, 5);
  EXPECT_EQ(truth[1].partner, 3);
  EXPECT_EQ(truth[0].session, 0);
  EXPECT_EQ(truth[0].pair, "00_01");
  EXPECT_EQ(truth[0].cloud.size(), 100u);  // HD points with the same id excluded
  EXPECT_EQ(truth[1].id, 5);
  EXPECT_EQ(truth[1].session, 1);
  ASSERT_EQ(truth[1].cloud.size(), 100u);
  EXPECT_NEAR(truth[1].cloud.points[0].x, 100.05f, 1e-3f);  // placed with the true pose

  // Clusters as `ltmapper map objects` writes them: object 0 = truth 3, object 1 = half of truth 5.
  const std::string od = (dir / "objects").string();
  WriteText(od + "/objects.csv",
            "id,session,reference,class,change,partner,track,points,cx,cy,cz,min_x,min_y,min_z,max_x,max_y,max_z\n"
            "0,1,0,nd_strong,moved,1,0,100,0,0,0,0,0,0,0,0,0\n"
            "1,1,0,pd_strong,appeared,-1,1,50,0,0,0,0,0,0,0,0,0\n");
  PointCloud all = Grid(10, 10);
  all.append(Grid(5, 10, 100.f, 0.f));
  all.object.assign(all.size(), 0);
  for (std::size_t i = 100; i < all.size(); ++i) all.object[i] = 1;
  io::WritePly(od + "/objects.ply", all);
  const auto clusters = ReadObjectClusters(od);
  ASSERT_EQ(clusters.size(), 2u);
  EXPECT_EQ(clusters[0].pair, "00_01");
  EXPECT_EQ(clusters[0].change, "disappeared");  // from the class column
  EXPECT_EQ(clusters[1].change, "appeared");
  EXPECT_EQ(clusters[1].cloud.size(), 50u);
  EXPECT_TRUE(clusters[0].moved);
  EXPECT_EQ(clusters[0].partner, 1);
  EXPECT_FALSE(clusters[1].moved);
  EXPECT_EQ(clusters[1].partner, -1);
  EXPECT_EQ(clusters[1].track, 1);
  const auto r = EvaluateObjects(truth, clusters, Cfg());
  EXPECT_TRUE(r.objects[0].found);
  EXPECT_TRUE(r.objects[1].found);  // IoU exactly 0.5
  EXPECT_NEAR(r.objects[1].best_iou, 0.5, 1e-12);
  // Observable: the objects most of whose change the other session observed (object 3 only).
  EXPECT_EQ(r.all.truth_objects, 2u);
  EXPECT_EQ(r.observable.truth_objects, 1u);
  EXPECT_EQ(r.observable.found, 1u);
  EXPECT_EQ(r.observable.clusters, 2u);
  // And per pair: the pair's clusters against its observable objects (recall 1 of 1, not 2 of 2
  // with the coverage difference counted).
  ASSERT_EQ(r.observable_per_pair.size(), 1u);
  EXPECT_EQ(r.observable_per_pair[0].name, "00_01 observable");
  EXPECT_EQ(r.observable_per_pair[0].truth_objects, 1u);
  EXPECT_EQ(r.observable_per_pair[0].found, 1u);
  EXPECT_EQ(r.observable_per_pair[0].clusters, 2u);
  Report rep;
  rep.objects = r;
  EXPECT_NEAR(*JsonNumber(ToJson(rep), "objects.observable_per_pair.0.recall"), 1.0, 1e-9);
  EXPECT_NE(ToMarkdown(rep).find("| 00_01 observable | 1 | 1 | 2 |"), std::string::npos);
  EXPECT_THROW(LoadSimObjectTruth((dir / "sim").string(), "00_05", GlobalTruthMapping(Pose::Identity(), "identity"), Cfg()), Error);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace ltm::eval
