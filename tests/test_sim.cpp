// Simulator: determinism, truth consistency (re-cast rays), HD-free static worlds, LD objects
// seen exactly where they exist, drift size, sessions loading back, config files, CLI.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/sim/sim.hpp"
#include "test_util.hpp"

#include <gtest/gtest.h>

#include <array>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>

namespace ltm::sim {
namespace {

namespace fs = std::filesystem;

// Every regular file under `dir`, relative path -> contents.
std::map<std::string, std::string> Files(const std::string& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) out[fs::relative(e.path(), dir).string()] = test::ReadText(e.path().string());
  }
  return out;
}

std::string Name(const char* prefix, int i) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%s%02d", prefix, i);
  return buf;
}
std::string ScanName(int k) { return io::layout::KeyframeDirName(k); }  // "000123", as the scans

// One simulated tiny scenario shared by the tests of this file (a few tenths of a second).
class SimTruth : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir();
    report_ = new SimReport(Simulate(TinyConfig(), dir_->str(), 2));
  }
  static void TearDownTestSuite() {
    delete report_;
    delete dir_;
  }
  static std::string Out() { return dir_->str(); }
  static test::TempDir* dir_;
  static SimReport* report_;
};
test::TempDir* SimTruth::dir_ = nullptr;
SimReport* SimTruth::report_ = nullptr;

TEST_F(SimTruth, WritesEveryDocumentedFile) {
  const SimConfig cfg = TinyConfig();
  EXPECT_EQ(report_->sessions, cfg.sessions);
  EXPECT_EQ(report_->keyframes, std::size_t(cfg.sessions * cfg.keyframes));
  EXPECT_GT(report_->ld_objects, 5u);
  EXPECT_GT(report_->hd_points, 0u);
  EXPECT_GT(report_->ld_points, 0u);
  for (const char* f : {"truth/scenario.yaml", "truth/objects.csv", "truth/hd_actors.csv", "truth/pair_00_01/pd_strong.pcd",
                        "truth/pair_00_01/pd_weak.pcd", "truth/pair_00_01/nd_strong.pcd",
                        "truth/pair_00_01/nd_weak.pcd", "truth/pair_00_01/changes.ply",
                        "truth/pair_00_01/objects_pd_strong.pcd", "truth/pair_00_01/objects_pd_weak.pcd",
                        "truth/pair_00_01/objects_nd_strong.pcd", "truth/pair_00_01/objects_nd_weak.pcd",
                        "truth/pair_00_01/objects_changes.ply"}) {
    EXPECT_TRUE(fs::exists(Out() + "/" + f)) << f;
  }
  for (int s = 0; s < cfg.sessions; ++s) {
    const std::string t = Out() + "/truth/" + Name("session_", s);
    for (const char* f : {"/poses_world.txt", "/origin.txt", "/static_world.pcd", "/static_world.ply"}) {
      EXPECT_TRUE(fs::exists(t + f)) << t + f;
    }
    EXPECT_EQ(io::ListIndexedFiles(t + "/labels", ".ply").size(), std::size_t(cfg.keyframes));
  }
  // The resolved config reads back into the same config.
  SimConfig back;
  io::LoadConfig(Out() + "/truth/scenario.yaml", back);
  EXPECT_EQ(ConfigToString(back), ConfigToString(cfg));
}

TEST_F(SimTruth, SessionsLoadBackWithDriftedPosesAndSameScans) {
  const SimConfig cfg = TinyConfig();
  Simulator sim(cfg, 1);
  for (int s = 0; s < cfg.sessions; ++s) {
    io::SessionLoadOptions opt;
    opt.load_clouds = true;
    opt.require_g2o = true;
    const Session session = io::LoadSession(Out() + "/sessions/" + Name("session_", s), opt);
    ASSERT_EQ(int(session.keyframes.size()), cfg.keyframes);
    EXPECT_EQ(int(session.odometry.size()), cfg.keyframes - 1);
    const auto& drifted = sim.T_session_sensor_drifted(s);
    const auto truth = io::ReadKittiPoses(Out() + "/truth/" + Name("session_", s) + "/poses_world.txt");
    const Pose origin = io::ReadTransform(Out() + "/truth/" + Name("session_", s) + "/origin.txt");
    ASSERT_EQ(int(truth.size()), cfg.keyframes);
    for (int k = 0; k < cfg.keyframes; ++k) {
      const Keyframe& kf = session.keyframes[std::size_t(k)];
      EXPECT_LT((kf.T_session_sensor.translation() - drifted[std::size_t(k)].translation()).norm(), 1e-4);
      EXPECT_LT((truth[std::size_t(k)].translation() - sim.T_world_sensor(s)[std::size_t(k)].translation()).norm(), 1e-4);
      // Same points in the same order in the PCD and the labelled PLY.
      const PointCloud labels = io::ReadPly(Out() + "/truth/" + Name("session_", s) + "/labels/" + ScanName(k) + ".ply");
      ASSERT_EQ(kf.cloud->size(), labels.size());
      ASSERT_EQ(labels.cls.size(), labels.size());
      for (std::size_t i = 0; i < labels.size(); i += 97) {
        EXPECT_EQ(kf.cloud->points[i].x, labels.points[i].x);
        EXPECT_EQ(kf.cloud->points[i].z, labels.points[i].z);
      }
    }
    // The origin is the hidden offset: true session-frame poses = origin^-1 * world poses.
    const auto local = sim.T_session_sensor_true(s);
    EXPECT_LT((origin.inverse() * truth[3]).translation().isApprox(local[3].translation(), 1e-4) ? 0.0 : 1.0, 0.5);
  }
}

TEST_F(SimTruth, RecastRaysMatchWrittenLabels) {
  const SimConfig cfg = TinyConfig();
  Simulator sim(cfg, 2);
  std::size_t checked = 0, match = 0, dynamic = 0, ld = 0;
  for (int s = 0; s < cfg.sessions; ++s) {
    for (int k : {0, 7, 14}) {
      const PointCloud labels = io::ReadPly(Out() + "/truth/" + Name("session_", s) + "/labels/" + ScanName(k) + ".ply");
      const Pose T = sim.T_world_sensor(s)[std::size_t(k)];
      std::vector<Eigen::Vector3f> dirs;
      std::vector<std::size_t> idx;
      for (std::size_t i = 0; i < labels.size(); ++i) {
        // Every HD / LD point and a sample of the permanent ones.
        if (labels.object[i] < 0 && i % 25 != 0) continue;
        const Eigen::Vector3d d = T.linear() * labels.points[i].xyz().cast<double>().normalized();
        dirs.push_back(d.cast<float>());
        idx.push_back(i);
      }
      const auto hits = sim.CastRays(s, k, T.translation(), dirs);
      for (std::size_t m = 0; m < idx.size(); ++m) {
        const std::size_t i = idx[m];
        ++checked;
        dynamic += labels.cls[i] == PointClass::kHD;
        ld += labels.cls[i] == PointClass::kStatic && labels.object[i] >= 0;
        const double range = labels.points[i].xyz().norm();
        if (hits[m].hit && hits[m].cls == labels.cls[i] && hits[m].object == labels.object[i] &&
            std::abs(hits[m].range - range) < 6 * cfg.range_noise_m + 1e-3) {
          ++match;
        }
      }
    }
  }
  EXPECT_GT(dynamic, 20u);
  EXPECT_GT(ld, 20u);
  // Rays re-cast through float point coordinates can slip off an edge: allow 1 %.
  EXPECT_GE(double(match), 0.99 * double(checked)) << match << " of " << checked;
}

TEST_F(SimTruth, StaticWorldHasNoHdPointsAndOnlyPresentObjects) {
  const SimConfig cfg = TinyConfig();
  Simulator sim(cfg, 1);
  for (int s = 0; s < cfg.sessions; ++s) {
    const PointCloud w = io::ReadPly(Out() + "/truth/" + Name("session_", s) + "/static_world.ply");
    ASSERT_GT(w.size(), 1000u);
    ASSERT_EQ(w.cls.size(), w.size());
    EXPECT_EQ(io::ReadPcd(Out() + "/truth/" + Name("session_", s) + "/static_world.pcd").size(), w.size());
    for (std::size_t i = 0; i < w.size(); ++i) {
      ASSERT_EQ(w.cls[i], PointClass::kStatic) << "point " << i;
      if (w.object[i] >= 0) {
        ASSERT_TRUE(sim.IsPresent(w.object[i], s)) << "object " << w.object[i] << " session " << s;
      }
    }
  }
}

// A moved container is two LD objects that name each other as partners: the same box, one present
// up to the change session, the other from it on; no other object has a partner. The truth file
// carries the column.
TEST_F(SimTruth, MovedContainersNameEachOther) {
  const SimConfig cfg;  // the default scenario: its lots hold the containers
  Simulator sim(cfg, 1);
  const auto& objects = sim.ld_objects();
  std::size_t moves = 0;
  for (const auto& o : objects) {
    if (o.partner < 0) continue;
    ASSERT_LT(std::size_t(o.partner), objects.size());
    const auto& p = objects[std::size_t(o.partner)];
    EXPECT_EQ(p.partner, o.id);
    EXPECT_EQ(o.cls, "container");
    EXPECT_EQ(p.cls, "container");
    const auto extents = [](const LdObjectInfo& x) {  // longer, shorter xy side, height: lots face any street
      const Eigen::Vector3d e = x.box_max - x.box_min;
      return Eigen::Vector3d(std::max(e.x(), e.y()), std::min(e.x(), e.y()), e.z());
    };
    EXPECT_LT((extents(o) - extents(p)).norm(), 1e-3);
    const auto& first = o.present_in.front() == 0 ? o : p;
    const auto& second = o.present_in.front() == 0 ? p : o;
    EXPECT_EQ(first.present_in.back() + 1, second.present_in.front());
    EXPECT_EQ(second.present_in.back(), cfg.sessions - 1);
    moves += o.id < o.partner;
  }
  EXPECT_EQ(moves, std::size_t(cfg.ld_containers));
  std::ifstream csv(Out() + "/truth/objects.csv");
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header.substr(header.rfind(',') + 1), "partner");
}

TEST_F(SimTruth, LdObjectsSeenExactlyWhereTheyExist) {
  const SimConfig cfg = TinyConfig();
  Simulator sim(cfg, 1);
  const auto& objects = sim.ld_objects();
  std::map<std::pair<int, int>, std::size_t> points;  // (object, session) -> labelled points
  for (int s = 0; s < cfg.sessions; ++s) {
    for (int k = 0; k < cfg.keyframes; ++k) {
      const PointCloud l = io::ReadPly(Out() + "/truth/" + Name("session_", s) + "/labels/" + ScanName(k) + ".ply");
      for (std::size_t i = 0; i < l.size(); ++i) {
        if (l.cls[i] == PointClass::kStatic && l.object[i] >= 0) ++points[{l.object[i], s}];
      }
    }
  }
  std::size_t seen_present = 0;
  for (const auto& o : objects) {
    for (int s = 0; s < cfg.sessions; ++s) {
      const std::size_t n = points[{o.id, s}];
      if (!sim.IsPresent(o.id, s)) {
        EXPECT_EQ(n, 0u) << o.cls << " " << o.id << " absent from session " << s;
      } else if (n > 0) {
        ++seen_present;
      }
    }
  }
  EXPECT_GE(seen_present, objects.size() / 2);
  // Object change truth: PD on objects new in the query, ND on objects gone from it.
  const PointCloud ch = io::ReadPly(Out() + "/truth/pair_00_01/objects_changes.ply");
  ASSERT_GT(ch.size(), 0u);
  std::set<PointClass> classes;
  for (std::size_t i = 0; i < ch.size(); ++i) {
    classes.insert(ch.cls[i]);
    const bool in0 = sim.IsPresent(ch.object[i], 0), in1 = sim.IsPresent(ch.object[i], 1);
    if (ch.cls[i] == PointClass::kPDStrong || ch.cls[i] == PointClass::kPDWeak) {
      EXPECT_TRUE(in1 && !in0);
    } else {
      EXPECT_TRUE(in0 && !in1);
    }
  }
  EXPECT_TRUE(classes.count(PointClass::kPDStrong)) << "the revealed structure gives strong PD";
  EXPECT_TRUE(classes.count(PointClass::kPDWeak));
  EXPECT_TRUE(classes.count(PointClass::kNDStrong));
  EXPECT_TRUE(classes.count(PointClass::kNDWeak)) << "the object behind the hoarding gives weak ND";
  std::size_t total = 0;
  for (const auto& p : report_->pairs) {
    total += p.objects_pd_strong + p.objects_pd_weak + p.objects_nd_strong + p.objects_nd_weak;
  }
  EXPECT_EQ(total, ch.size());
}

// Exact point lookup (the change clouds are subsets of the static worlds, same coordinates).
std::set<std::array<float, 3>> PointSet(const PointCloud& c) {
  std::set<std::array<float, 3>> s;
  for (const auto& p : c.points) s.insert({p.x, p.y, p.z});
  return s;
}

// The LD change truth comes twice: strong / weak by the scans' own rays (beam truth, the pair
// folder) and by a ray cast straight at each point (exact_ray/). Same points; a beam passes near
// a point only where the scan pattern has one, so the beam truth sees through no more often:
// its strong ND and weak PD are (nearly) subsets of the exact-ray ones, and each label is kept.
TEST_F(SimTruth, BeamTruthBesideExactRayTruth) {
  const std::string pair = Out() + "/truth/pair_00_01", exact = io::layout::ExactRayTruthDir(pair);
  std::size_t beam_seen = 0, exact_seen = 0, both = 0;
  for (const char* k : {"nd_strong", "pd_weak"}) {
    const auto b = PointSet(io::ReadPcd(pair + "/objects_" + std::string(k) + ".pcd"));
    const auto e = PointSet(io::ReadPcd(exact + "/objects_" + std::string(k) + ".pcd"));
    beam_seen += b.size(), exact_seen += e.size();
    for (const auto& p : b) both += e.count(p);
  }
  std::printf("seen through: beam truth %zu, exact-ray truth %zu, both %zu\n", beam_seen, exact_seen, both);
  EXPECT_GT(beam_seen, 0u);
  EXPECT_GE(double(both), 0.98 * double(beam_seen));
  const PointCloud bc = io::ReadPly(pair + "/objects_changes.ply"), ec = io::ReadPly(exact + "/objects_changes.ply");
  EXPECT_EQ(PointSet(bc), PointSet(ec));
}

// FiredRays are the rays CastScan fires: without noise and dropout, casting them again gives the
// scan's points, one by one in its order (rays with a return in range), from a moving sweep too.
TEST(Sim, FiredRaysAreTheScansRays) {
  SimConfig cfg = TinyConfig();
  cfg.range_noise_m = 0.0;
  cfg.dropout = 0.0;
  cfg.ego_speed_mps = 15.0;
  cfg.sweep = "distorted";
  Simulator sim(cfg, 2);
  const int k = 3;
  const PointCloud scan = sim.CastScan(0, k);  // each point in the sensor frame of its firing
  std::vector<Eigen::Vector3f> origins, dirs;
  sim.FiredRays(0, k, &origins, &dirs);
  ASSERT_EQ(dirs.size(), std::size_t(cfg.beams) * cfg.columns);
  const auto hits = sim.CastRays(0, k, origins, dirs);
  const std::vector<Pose> sweep = sim.SweepPoses(0, k);
  std::size_t n = 0, close = 0;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    if (!hits[i].hit || hits[i].range < cfg.min_range_m || hits[i].range > cfg.max_range_m) continue;
    if (n < scan.size()) {
      const Eigen::Vector3f world = origins[i] + hits[i].range * dirs[i];
      const Eigen::Vector3f fired = (sweep[i % std::size_t(cfg.columns)].cast<float>() * scan.points[n].xyz());
      close += (world - fired).norm() < 1e-3f;
    }
    ++n;
  }
  EXPECT_EQ(n, scan.size());
  EXPECT_GE(double(close), 0.999 * double(scan.size()));
}

TEST_F(SimTruth, UnobservedStaticSurfacesAreStrongPdAndWeakNd) {
  const SimConfig cfg = TinyConfig();
  Simulator sim(cfg, 2);
  const std::string pair = Out() + "/truth/pair_00_01/", exact = io::layout::ExactRayTruthDir(pair) + "/";
  const auto pds = PointSet(io::ReadPcd(pair + "pd_strong.pcd"));
  std::set<std::array<float, 3>> any, any_exact;  // every change point of the beam / exact-ray truth
  for (const char* f : {"pd_strong", "pd_weak", "nd_strong", "nd_weak"}) {
    const auto s = PointSet(io::ReadPcd(pair + f + ".pcd"));
    any.insert(s.begin(), s.end());
    const auto e = PointSet(io::ReadPcd(exact + f + ".pcd"));
    any_exact.insert(e.begin(), e.end());
    // The object-only truth is part of the full truth.
    for (const auto& p : PointSet(io::ReadPcd(pair + "objects_" + f + ".pcd"))) EXPECT_TRUE(s.count(p)) << f;
  }
  // Permanent structure is only ever strong PD (query side) or weak ND (central side).
  const PointCloud ch = io::ReadPly(pair + "changes.ply");
  std::size_t permanent = 0;
  for (std::size_t i = 0; i < ch.size(); ++i) {
    if (ch.object[i] >= 0) continue;
    ++permanent;
    EXPECT_TRUE(ch.cls[i] == PointClass::kPDStrong || ch.cls[i] == PointClass::kNDWeak) << int(ch.cls[i]);
  }
  EXPECT_GT(permanent, 0u);
  auto min_distance = [&](const Eigen::Vector3f& p, int s) {
    double best = 1e30;
    for (const auto& T : sim.T_world_sensor(s)) best = std::min(best, (T.translation() - p.cast<double>()).norm());
    return best;
  };
  // Query static points beyond the max range of every central keyframe: strong PD.
  const PointCloud query = io::ReadPly(Out() + "/truth/session_01/static_world.ply");
  std::size_t far = 0;
  for (std::size_t i = 0; i < query.size(); i += 7) {
    if (query.object[i] >= 0 || min_distance(query.points[i].xyz(), 0) <= cfg.max_range_m + 1.0) continue;
    ++far;
    const auto& p = query.points[i];
    ASSERT_TRUE(pds.count({p.x, p.y, p.z})) << p.x << " " << p.y << " " << p.z;
  }
  EXPECT_GT(far, 10u);
  // Central static points a beam of a query scan ended on (within 10 cm): in no change file of the
  // beam truth.
  const PointCloud central = io::ReadPly(Out() + "/truth/session_00/static_world.ply");
  std::size_t sampled = 0;
  for (int k : {2, 9}) {
    std::vector<Eigen::Vector3f> origins, dirs;
    sim.FiredRays(1, k, &origins, &dirs);
    const auto hits = sim.CastRays(1, k, origins, dirs);
    PointCloud ends;
    for (std::size_t i = 0; i < dirs.size(); ++i)
      if (hits[i].hit && hits[i].object < 0 && hits[i].range >= cfg.min_range_m && hits[i].range <= cfg.max_range_m) {
        const Eigen::Vector3f e = origins[i] + hits[i].range * dirs[i];
        ends.push_back(e.x(), e.y(), e.z());
      }
    const geometry::KdTree tree(ends);
    for (std::size_t i = 0; i < central.size(); ++i) {
      const auto& p = central.points[i];
      if (central.object[i] >= 0 || tree.CountWithin(p.xyz(), 0.1f, 1) == 0) continue;
      ++sampled;
      ASSERT_FALSE(any.count({p.x, p.y, p.z})) << "a beam of query keyframe " << k << " ended on " << p.x << " " << p.y;
    }
  }
  EXPECT_GT(sampled, 100u);
  // Central static points a query ray cast straight at them hits head-on (within 5 cm): in no
  // change file of the exact-ray truth.
  std::size_t observed = 0;
  for (int k : {2, 9}) {
    const Pose T = sim.T_world_sensor(1)[std::size_t(k)];
    std::vector<Eigen::Vector3f> dirs;
    std::vector<std::size_t> idx;
    for (std::size_t i = 0; i < central.size(); i += 11) {
      const Eigen::Vector3d d = central.points[i].xyz().cast<double>() - T.translation();
      if (central.object[i] >= 0 || d.norm() > cfg.max_range_m - 1.0 || d.norm() < cfg.min_range_m) continue;
      const Eigen::Vector3d ds = T.linear().transpose() * d;
      const double el = std::atan2(ds.z(), std::hypot(ds.x(), ds.y())) * 180.0 / M_PI;
      if (el < cfg.fov_down_deg || el > cfg.fov_up_deg) continue;
      dirs.push_back(d.normalized().cast<float>());
      idx.push_back(i);
    }
    const auto hits = sim.CastRays(1, k, T.translation(), dirs);
    for (std::size_t m = 0; m < idx.size(); ++m) {
      const auto& p = central.points[idx[m]];
      const double r = (p.xyz().cast<double>() - T.translation()).norm();
      if (hits[m].hit && hits[m].object < 0 && hits[m].cos_incidence > 0.5 && std::abs(hits[m].range - r) < 0.05) {
        ++observed;
        ASSERT_FALSE(any_exact.count({p.x, p.y, p.z})) << "observed by query keyframe " << k << ": " << p.x << " " << p.y;
      }
    }
  }
  EXPECT_GT(observed, 100u);
  EXPECT_GT(report_->pairs[0].nd_weak, report_->pairs[0].objects_nd_weak);
}

// "Observed" means a ray of the other session ended on the point's own surface near it. A ray
// cast straight at a point that ends on another surface within the along-ray band (the side of a
// box passed at a grazing angle, in front of a point on its back; a curb before the road behind
// it) did not observe it. Central static points (their surface normal from a central ray that hit
// them) that every query keyframe's straight ray reaches only that way are weak ND in the
// exact-ray truth.
TEST_F(SimTruth, ARayEndingOnAnotherSurfaceDidNotObserveThePoint) {
  const SimConfig cfg = TinyConfig();
  Simulator sim(cfg, 2);
  const auto weak = PointSet(io::ReadPcd(io::layout::ExactRayTruthDir(Out() + "/truth/pair_00_01") + "/nd_weak.pcd"));
  const PointCloud central = io::ReadPly(Out() + "/truth/session_00/static_world.ply");
  const PointCloud query = io::ReadPly(Out() + "/truth/session_01/static_world.ply");
  const geometry::KdTree scanned(query);
  const double tol = cfg.visibility_tolerance_m;
  // A straight ray from keyframe k of session s at p: its hit, or none when p is out of range / FOV.
  auto cast = [&](int s, int k, const Eigen::Vector3f& p, double* r) -> std::optional<RayHit> {
    const Pose& T = sim.T_world_sensor(s)[std::size_t(k)];
    const Eigen::Vector3d d = p.cast<double>() - T.translation();
    *r = d.norm();
    const Eigen::Vector3d ds = T.linear().transpose() * d;
    const double el = std::atan2(ds.z(), std::hypot(ds.x(), ds.y())) * 180.0 / M_PI;
    if (*r < cfg.min_range_m || *r > cfg.max_range_m || el < cfg.fov_down_deg || el > cfg.fov_up_deg) return std::nullopt;
    return sim.CastRays(s, k, T.translation(), {d.normalized().cast<float>()})[0];
  };
  std::size_t other_surface_only = 0;
  for (std::size_t i = 0; i < central.size(); i += 5) {
    const Eigen::Vector3f p = central.points[i].xyz();
    if (central.object[i] >= 0 || scanned.CountWithin(p, float(tol), 1) > 0) continue;
    // Its surface: the normal where central rays hit it, the same from every one (not an edge).
    Eigen::Vector3f n = Eigen::Vector3f::Zero();
    bool edge = false;
    for (int k = 0; k < cfg.keyframes; ++k) {
      double r = 0.0;
      const auto h = cast(0, k, p, &r);
      if (!h || !h->hit || std::abs(h->range - r) > tol) continue;
      edge = edge || (!n.isZero() && std::abs(n.dot(h->normal)) < 0.95f);
      n = h->normal;
    }
    if (n.isZero() || edge) continue;
    bool own = false, other = false, unsure = false;
    for (int k = 0; k < cfg.keyframes && !own; ++k) {
      double r = 0.0;
      const auto h = cast(1, k, p, &r);
      if (!h || !h->hit || h->cls == PointClass::kHD || h->object >= 0) continue;
      const double band = std::max(tol, std::min(tol / std::max(double(h->cos_incidence), 1e-6), cfg.visibility_grazing_max_m));
      if (std::abs(h->range - r) > band) continue;
      const Eigen::Vector3f at = sim.T_world_sensor(1)[std::size_t(k)].translation().cast<float>() +
                                 h->range * (p.cast<double>() - sim.T_world_sensor(1)[std::size_t(k)].translation()).normalized().cast<float>();
      const double off = std::abs(n.dot(at - p));  // clearly off its plane (a facet's normal is not the point's)
      (off <= tol ? own : off > tol + 0.1 ? other : unsure) = true;
    }
    if (own || unsure || !other) continue;
    ++other_surface_only;
    EXPECT_TRUE(weak.count({p.x(), p.y(), p.z()})) << p.transpose();
  }
  EXPECT_GT(other_surface_only, 0u);
}

TEST(Sim, SameSeedSameBytesAnyThreadsOtherSeedDiffers) {
  SimConfig cfg = TinyConfig();
  cfg.keyframes = 6;
  test::TempDir a, b, c;
  Simulate(cfg, a.str(), 1);
  Simulate(cfg, b.str(), 2);
  const auto fa = Files(a.str()), fb = Files(b.str());
  ASSERT_EQ(fa.size(), fb.size());
  for (const auto& [name, bytes] : fa) {
    ASSERT_TRUE(fb.count(name)) << name;
    EXPECT_TRUE(bytes == fb.at(name)) << name << " differs between runs";
  }
  cfg.seed += 1;
  Simulate(cfg, c.str(), 2);
  const auto fc = Files(c.str());
  EXPECT_NE(fa.at("sessions/session_00/Scans/000000.pcd"), fc.at("sessions/session_00/Scans/000000.pcd"));
  EXPECT_NE(fa.at("truth/objects.csv"), fc.at("truth/objects.csv"));
}

TEST(Sim, DriftIsAboutTheConfiguredPercent) {
  // A straight 300 m drive, 1 m steps: endpoint error relative to the distance.
  std::vector<Pose> straight;
  for (int i = 0; i <= 300; ++i) {
    Pose T = Pose::Identity();
    T.translation() = Eigen::Vector3d(i, 0, 0);
    straight.push_back(T);
  }
  const SimConfig cfg;
  double sum = 0;
  const int runs = 40;
  for (int r = 0; r < runs; ++r) {
    const auto d = DriftPoses(straight, cfg, std::uint64_t(r));
    ASSERT_EQ(d.size(), straight.size());
    EXPECT_TRUE(d[0].isApprox(straight[0]));
    sum += (d.back().translation() - straight.back().translation()).norm() / 300.0;
  }
  const double mean = sum / runs;
  EXPECT_GT(mean, 0.002) << mean;
  EXPECT_LT(mean, 0.03) << mean;
  SimConfig none;
  none.drift_scale = none.drift_translation = none.drift_yaw_deg = none.drift_z_m = 0.0;
  const auto d = DriftPoses(straight, none, 3);
  EXPECT_LT((d.back().translation() - straight.back().translation()).norm(), 1e-9);
}

// A sweep that takes time: the distorted scan is right only with each column's own pose, the
// deskewed scan is that same cloud in the keyframe's frame, and the instant scan is unchanged.
TEST(Sim, MotionDistortedAndDeskewedSweeps) {
  SimConfig cfg = TinyConfig();
  cfg.ego_speed_mps = 15.0;  // 1.5 m per 0.1 s sweep: far beyond the sampling
  const int k = 5;
  Simulator instant(cfg, 2);
  const Pose T = instant.T_world_sensor(0)[std::size_t(k)];
  const PointCloud w0 = geometry::Transform(instant.CastScan(0, k), T);
  cfg.sweep = "distorted";
  Simulator distorted(cfg, 2);
  const PointCloud raw = distorted.CastScan(0, k);
  const std::vector<Pose> sweep = distorted.SweepPoses(0, k);
  ASSERT_EQ(sweep.size(), std::size_t(cfg.columns));
  EXPECT_NEAR((sweep.back().translation() - T.translation()).norm(), 1.5 * (cfg.columns - 1) / cfg.columns, 0.05);
  cfg.sweep = "deskewed";
  Simulator deskewed(cfg, 2);
  const PointCloud desk = deskewed.CastScan(0, k);
  ASSERT_EQ(raw.size(), desk.size());
  // A point is right when it lies on the first surface along the ray from where it was fired:
  // cast that ray again (noise-free) and compare ranges. Points come beam by beam, column by
  // column; the instant scan's points (from the keyframe pose) are right by construction.
  auto share_on_surface = [&](Simulator& sim, const PointCloud& world, const std::vector<Pose>& from) {
    std::size_t ok = 0;
    for (std::size_t i = 0; i < world.size(); ++i) {
      const Eigen::Vector3d o = from[i].translation(), q = world.points[i].xyz().cast<double>();
      const auto hit = sim.CastRays(0, k, o, {(q - o).normalized().cast<float>()});
      if (hit[0].hit && std::fabs(hit[0].range - (q - o).norm()) < 0.1) ++ok;
    }
    return double(ok) / double(world.size());
  };
  // The fire pose of each output point: dropped rays leave gaps, so match by direction's column.
  auto fire_poses = [&](const PointCloud& sensor_frame_raw) {
    std::vector<Pose> out;
    for (const PointXYZI& p : sensor_frame_raw.points) {
      const double az = std::atan2(double(p.y), double(p.x));
      const int c = int(std::lround((M_PI - az) / (2.0 * M_PI) * cfg.columns)) % cfg.columns;
      out.push_back(sweep[std::size_t(c)]);
    }
    return out;
  };
  const std::vector<Pose> fired = fire_poses(raw);
  const PointCloud naive = geometry::Transform(raw, T), fixed = geometry::Transform(desk, T);
  const double s_naive = share_on_surface(distorted, naive, std::vector<Pose>(naive.size(), T));
  const double s_fixed = share_on_surface(deskewed, fixed, fired);
  std::printf("points on the surface along their ray: distorted placed with the keyframe pose %.3f, deskewed %.3f\n",
              s_naive, s_fixed);
  EXPECT_GT(s_fixed, 0.97);
  EXPECT_LT(s_naive, s_fixed - 0.2);
  EXPECT_GT(w0.size(), 1000u);
}

// A distorted session as written (raw sweeps: per-point `time`, times.txt) loads deskewed with
// its own drifted odometry: close to the deskewed session's scans (the same rays moved by the true
// sweep poses), and its labelled truth is where the points truly are (the deskewed truth).
TEST(Sim, DistortedSessionLoadsDeskewed) {
  SimConfig cfg = TinyConfig();
  cfg.sessions = 1;
  cfg.ego_speed_mps = 15.0;  // 1.5 m per 0.1 s sweep
  test::TempDir a, b;
  cfg.sweep = "distorted";
  Simulate(cfg, a.str(), 2);
  cfg.sweep = "deskewed";
  Simulate(cfg, b.str(), 2);
  const Session raw = io::LoadSession(a.str() + "/sessions/session_00");
  const Session desk = io::LoadSession(b.str() + "/sessions/session_00");
  ASSERT_EQ(raw.keyframes.size(), desk.keyframes.size());
  std::vector<double> err, before;
  for (std::size_t k = 1; k < raw.keyframes.size(); k += 3) {
    ASSERT_TRUE(raw.keyframes[k].sweep.known);
    const auto p = io::KeyframeCloud(raw.keyframes[k]), q = io::KeyframeCloud(desk.keyframes[k]);
    const PointCloud as_written = io::ReadPcd(raw.keyframes[k].cloud_path);
    ASSERT_EQ(p->size(), q->size());
    ASSERT_EQ(as_written.time.size(), as_written.size());
    for (std::size_t i = 0; i < p->size(); ++i) {
      err.push_back(double((p->points[i].xyz() - q->points[i].xyz()).norm()));
      before.push_back(double((as_written.points[i].xyz() - q->points[i].xyz()).norm()));
    }
    const PointCloud la = io::ReadPly(a.str() + "/truth/session_00/labels/" + ScanName(int(k)) + ".ply");
    const PointCloud lb = io::ReadPly(b.str() + "/truth/session_00/labels/" + ScanName(int(k)) + ".ply");
    ASSERT_EQ(la.size(), lb.size());
    for (std::size_t i = 0; i < la.size(); ++i) ASSERT_LT((la.points[i].xyz() - lb.points[i].xyz()).norm(), 1e-4);
  }
  auto pct = [](std::vector<double> v, double q) {
    std::sort(v.begin(), v.end());
    return v[std::size_t(q * double(v.size() - 1))];
  };
  std::printf("raw sweep vs deskewed truth: median %.3f m, 99th %.3f m before; %.4f m, 99th %.4f m after deskewing\n",
              pct(before, 0.5), pct(before, 0.99), pct(err, 0.5), pct(err, 0.99));
  EXPECT_GT(pct(before, 0.5), 0.3);
  EXPECT_LT(pct(err, 0.5), 0.03);
  EXPECT_LT(pct(err, 0.99), 0.15);
}

TEST(Sim, ScanGeometry) {
  SimConfig cfg = TinyConfig();
  Simulator sim(cfg, 0);
  const PointCloud scan = sim.CastScan(0, 3);
  const std::size_t rays = std::size_t(cfg.beams) * cfg.columns;
  EXPECT_GT(scan.size(), rays / 2);
  EXPECT_LE(scan.size(), rays);
  for (const auto& p : scan.points) {
    const float r = p.xyz().norm();
    ASSERT_GE(r, cfg.min_range_m - 1e-3);
    ASSERT_LE(r, cfg.max_range_m + 1e-3);
    const double el = std::atan2(p.z, std::hypot(p.x, p.y)) * 180.0 / M_PI;
    ASSERT_GE(el, cfg.fov_down_deg - 1e-3);
    ASSERT_LE(el, cfg.fov_up_deg + 1e-3);
  }
  // The true origin is the hidden offset: world pose = origin * session pose.
  const auto local = sim.T_session_sensor_true(1);
  EXPECT_TRUE((sim.T_world_session(1) * local[4]).isApprox(sim.T_world_sensor(1)[4], 1e-9));
  EXPECT_THROW(sim.CastScan(5, 0), Error);
  EXPECT_THROW(sim.CastScan(0, 99), Error);
}

TEST(Sim, ConfigFilesListEveryKeyWithDefaults) {
  SimConfig def, file, rep;
  io::LoadConfig(std::string(LTM_SOURCE_DIR) + "/config/params_sim.yaml", file);
  EXPECT_EQ(ConfigToString(file), ConfigToString(def));
  io::LoadConfig(std::string(LTM_SOURCE_DIR) + "/config/params_sim_repetitive.yaml", rep);
  EXPECT_EQ(rep.scenario, "repetitive");
  const std::string text = test::ReadText(std::string(LTM_SOURCE_DIR) + "/config/params_sim.yaml");
  const ConfigFields fields = FieldsOf(def);
  for (const auto& f : fields.fields()) {
    const std::string leaf = f.key.substr(f.key.rfind('.') == std::string::npos ? 0 : f.key.rfind('.') + 1);
    EXPECT_NE(text.find(leaf + ":"), std::string::npos) << f.key;
  }
  SimConfig bad;
  bad.fov_up_deg = -30.0;
  EXPECT_THROW(CheckConfig(bad), Error);
  bad = SimConfig{};
  bad.extent_m = 60.0;
  EXPECT_THROW(CheckConfig(bad), Error);
}

TEST(Sim, RepetitiveScenarioBuilds) {
  SimConfig cfg = TinyConfig();
  cfg.scenario = "repetitive";
  Simulator sim(cfg, 0);
  EXPECT_GT(sim.triangles(), 1000u);
  EXPECT_GT(sim.CastScan(1, 2).size(), 1000u);
}

TEST(Sim, CommandLine) {
  test::TempDir dir;
  SimConfig cfg = TinyConfig();
  cfg.keyframes = 4;
  SimConfig copy = cfg;
  io::SaveConfigFields(dir / "tiny.yaml", FieldsOf(copy));
  std::string out;
  ASSERT_EQ(test::RunCli("sim --config " + dir / "tiny.yaml" + " --out " + dir / "out" + " --seed 3 --threads 1", &out), 0) << out;
  EXPECT_TRUE(fs::exists(dir / "out/sessions/session_01/Scans/000003.pcd")) << out;
  SimConfig back;
  io::LoadConfig(dir / "out/truth/scenario.yaml", back);
  EXPECT_EQ(back.seed, 3);
  test::WriteText(dir / "bad.yaml", "lidar:\n  beams: 64\n  bogus_key: 1\n");
  EXPECT_NE(test::RunCli("sim --config " + dir / "bad.yaml" + " --out " + dir / "out2", &out), 0);
  EXPECT_NE(out.find("bogus_key"), std::string::npos) << out;
}

}  // namespace
}  // namespace ltm::sim
