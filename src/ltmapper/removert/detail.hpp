// Private helpers of the removert module (not installed, not included outside this folder).
#pragma once

#include "ltmapper/removert/removert.hpp"

#include "ltmapper/removert/images.hpp"
#include "ltmapper/removert/tile_index.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

namespace ltm::removert::detail {

// The keyframe's scan (memory or file).
std::shared_ptr<const PointCloud> LoadScan(const WorldKeyframe& kf);
class SweepFrames;
// The scan a keyframe's votes are counted on: a raw sweep (per-point time, its session's motion
// known) as read, each point in the frame its column fired from, with *frames (when asked for)
// mapping the keyframe frame there (SweepFrames); a deskewed scan put back there the same way when
// `timing` is known (io::Reskew); any other scan as LoadScan gives it (*frames inactive).
std::shared_ptr<const PointCloud> LoadVoterScan(const WorldKeyframe& kf, const SweepTiming& timing,
                                                SweepFrames* frames);
// When the columns of deskewed scans fired, from how tightly their returns, re-skewed with it,
// fall on beams (sweep_timing.cpp; scans[i] swept with motions[i], returns beyond min_range_m);
// unknown when no timing piles them up more tightly than they are. On `threads` workers (0: all
// cores), with the result of one.
SweepTiming EstimateSweepTiming(const std::vector<PointCloud>& scans, const std::vector<SweepMotion>& motions,
                                double min_range_m, int threads);
// The keyframes' sensor positions (world frame), one point per keyframe, in keyframe order.
PointCloud Positions(const std::vector<WorldKeyframe>& keyframes);

// parallel_for over [0, n) inside a task_arena of `threads` (0 = default), grain 1.
using ltm::ParallelFor;  // core.hpp

// Per point: keyframes see through it at any LD resolution (seen), and whether any keyframe had
// a return in the window at its pixel at all (observed) (occlusion.cpp).
// same: not seen through, and at least ld_same_min_hits keyframes hit it on its surface plane
// (the other session has this surface; its map is only sparser there). `own_map` (the map the
// points come from) gives their normals. own_pixel (PD): also count the keyframes whose own pixel
// of the point has a return beyond it (seen_own); the ND pass leaves it empty.
struct Visibility {
  std::vector<bool> seen, observed, same;
  std::vector<bool> seen_own;  // with own_pixel: seen, or seen through by an upright point's own pixel, or
                               // passed by a beam that met nothing (PD strength)
};
// standing (optional, per point): the point stands on the other session's ground (a lower body,
// Missing's kRawAboveTheirGround), whose plane its level normal may be: the level-ground rule of
// `same` does not apply to it.
// other_map (optional): the keyframes' session map; with it, the beam test reads the incidence on
// the surfaces their beams met (HitSurfaces), and (ND) a point its own map drew twice (a displaced
// copy of a surface both maps hold) is not seen through.
Visibility SeenThroughBy(const PointCloud& points, const PointCloud& own_map,
                         const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                         int threads, bool own_pixel, const std::vector<bool>* standing = nullptr,
                         const PointCloud* other_map = nullptr);
// Per point of `v`: seen through by the pixels, or by more keyframes' beams that went through its
// place than ended near it (occlusion.cpp; SeenThroughBy's ND evidence).
std::vector<bool> SeenThroughVotes(const VisibilityVotes& v, const RemovertConfig& cfg);

// |normal z| below cos 45 deg: the surface is more upright than horizontal (a wall, a car's flank);
// above it, more horizontal (ground, a roof).
constexpr float kUprightNormalZ = 0.70710678f;
// |n1 . n2| at least cos 45 deg: two planes are parallel.
constexpr float kParallelCos = 0.70710678f;

// The at most kNeighbourhoodPoints nearest points of `cloud` within `radius` of p: how many, their
// mean offset from p, and the eigen decomposition (ascending) of their covariance.
constexpr std::size_t kNeighbourhoodPoints = 16;
struct Neighbourhood {
  int n = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();
  double reach = 0.0;  // [m] the farthest neighbour's distance
  Eigen::Matrix3d eigenvectors = Eigen::Matrix3d::Identity();
};
Neighbourhood FitNeighbourhood(const geometry::KdTree& tree, const PointCloud& cloud, const Eigen::Vector3f& p,
                               float radius);

// Unit normals of `points` from their neighbourhood in `map` (at most 16 nearest within
// radius_m): the PCA normal of a planar neighbourhood; for a line-like one (a far ground ring,
// a pole) the direction perpendicular to the line closest to vertical; +z with < 2 neighbours.
// planar (optional): per point, whether its normal is a plane's (else a line's, or none).
// rim (optional): per point of a plane, whether it lies at the rim of it: the mean of its
// neighbours off it along the plane by more than kRimOffset of their reach (a straight edge puts
// it at 4 / (3 pi) = 0.42 of it, a point inside a plane at 0; the bound lies halfway).
constexpr double kRimOffset = 0.21;

// SurfaceExtents (occlusion.cpp): how far around an ND point its upright surface goes on is
// measured up to kSurfaceExtentTols x ld.beam_tol_m (a beam that passed within the tolerance of a
// point seen at 84 deg incidence crosses its plane up to 10 tolerances from it), across gaps of at
// most kSurfaceGapTols x ld.beam_tol_m (the rows of a surface scanned from afar), on the map thinned
// to voxels of kSurfaceVoxelTols x ld.beam_tol_m (the extents are read to within that).
constexpr double kSurfaceExtentTols = 10.0, kSurfaceGapTols = 2.0, kSurfaceVoxelTols = 0.5;
std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const PointCloud& map,
                                             double radius_m, int threads,
                                             std::vector<bool>* planar = nullptr, std::vector<bool>* rim = nullptr);
// The same on `tree`, a kd-tree over `map` built already.
std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const geometry::KdTree& tree,
                                             const PointCloud& map, double radius_m, int threads,
                                             std::vector<bool>* planar = nullptr, std::vector<bool>* rim = nullptr);

// Points of `cloud` (world frame) moved into a keyframe's frame: p_local = T^-1 p.
PointCloud ToLocal(const PointCloud& cloud, const Pose& T_world_sensor);

// ---- LD as labels (ld_detection.cpp), shared with LD tile by tile (ld_tiles.cpp)
// kLdOutside: a point of a tile's window outside its core (decided by another tile).
enum LdLabel : std::uint8_t { kLdUnchanged = 0, kLdStrong, kLdWeak, kLdUnobserved, kLdResidue, kLdSame, kLdOutside };
struct LdLabels {
  std::vector<std::uint8_t> central, query;  // per map point: an LdLabel (ND of central, PD of query)
};
// DetectLd's decision for every point of both maps. The positions are every keyframe's of each
// session (the radius's distance term); the voters are the keyframes whose scans judge
// occlusion (those within sensor.max_range_m of the points give the same votes as all). `cfg`
// has its sensor resolved.
LdLabels LabelLd(const PointCloud& central_map, const PointCloud& query_map, const PointCloud& central_positions,
                 const PointCloud& query_positions, const std::vector<WorldKeyframe>& central_voters,
                 const std::vector<WorldKeyframe>& query_voters, const RemovertConfig& cfg, int threads);
// The labelled points as DetectLd's clouds (map order) and counts (seconds left 0).
LdResult LdFromLabels(const PointCloud& central_map, const PointCloud& query_map, const LdLabels& labels);

// ---- the session map and the HD decision (hd_removal.cpp), shared with the tiles (tiles.cpp)

// The map voxel's index along one axis: floor(v / voxel_m), the grid of geometry::VoxelDownsample.
std::int64_t VoxelIndex(float v, double voxel_m);
// A box of map voxels in xy, [x0, x1) x [y0, y1) (voxel indices): a tile's core or its core plus margin.
struct VoxelBox {
  std::int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool Contains(std::int64_t ix, std::int64_t iy) const { return ix >= x0 && ix < x1 && iy >= y0 && iy < y1; }
  // [m] xy distance from (x, y) to the box (voxels of voxel_m).
  double DistanceM(double voxel_m, double x, double y) const {
    const double dx = std::max({double(x0) * voxel_m - x, 0.0, x - double(x1) * voxel_m});
    const double dy = std::max({double(y0) * voxel_m - y, 0.0, y - double(y1) * voxel_m});
    return std::hypot(dx, dy);
  }
};
// One keyframe's scan for the map: range filtered, in the world frame, clipped to `clip` (when
// given) and voxelised. Clipping keeps the order of the points, so a voxel inside the box sums
// the same points in the same order as without it.
PointCloud ScanForMap(const WorldKeyframe& kf, const RemovertConfig& cfg, const VoxelBox* clip);
// Keyframes per map batch: a batch's scans are voxelised together (one centroid per voxel).
constexpr std::size_t kMapBatch = 32;
// The map of keyframes that hold the session positions `slots` (ascending): keyframe slot s is in
// batch s / kMapBatch, and the batches' maps are merged as a binary tree over batch numbers (the
// two halves of a node: per-voxel mean of their centroids; a node with one non-empty half is that
// half, exactly). A voxel's centroid is therefore the same nested mean for any subset of the
// session's keyframes that holds every keyframe with points in that voxel: a tile's map equals
// the session map in every voxel inside its box, bit for bit. `clip` (null = none) keeps the
// scan points whose voxel lies in the box. Memory: one batch of scans and one pending map per
// tree level (log2 of the batches).
PointCloud BuildMap(const std::vector<WorldKeyframe>& keyframes, const std::vector<std::size_t>& slots,
                    const RemovertConfig& cfg, int threads, const VoxelBox* clip);
// What HD removal decided for every map point.
struct HdDecision {
  enum : std::uint8_t { kStatic = 0, kReverted, kRemoved, kDilated };
  std::vector<std::uint8_t> state;  // per map point
  int levels = 0;                   // removal resolutions
  std::vector<bool> candidate_at;   // [point * levels + level]: a removal candidate at that resolution
};
HdDecision DecideHd(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                    int threads);
// The local ground under p: the lowest z of `low` in p's cell and the 8 around it, at most p.z.
inline float GroundNear(const geometry::LowestGrid& low, const PointXYZI& p) {
  const Eigen::Vector3f q(p.x, p.y, p.z);
  return std::min(p.z, low.Under(q, q, 1));
}
// A removed body's other returns (hd_bodies.cpp): per keyframe, the clusters of its returns above
// the ground no longer than hd.body_max_m, at least hd.remove_min_ratio of them in removed map voxels
// (state kRemoved / kDilated) and their map points' `votes` (the removal resolutions') pooled passing
// removal's test; a map point every keyframe returning in its voxel met in such a cluster becomes
// kDilated. Needs cfg's sensor resolved (else, or with hd.body_max_m 0, nothing).
void CompleteBodies(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                    const VisibilityVotes& votes, int threads, std::vector<std::uint8_t>* state);
// The static and HD maps of the points with (*include)[i] (null: all) and their stats.
HdResult SplitHd(const PointCloud& map, const HdDecision& decision, const std::vector<bool>* include);

// ---- tiles (tiles.cpp), shared with the tile jobs from files (tile_jobs.cpp)
// Clouds each in voxel order (x, then y, then z voxel index; VoxelDownsample's order: a tile's
// part, a subsequence of its map) merged into one stream in voxel order: emit() gets it in pieces
// of at most kMergePiece points. Memory: the parts and one piece.
constexpr std::size_t kMergePiece = 1 << 16;
void MergeInVoxelOrder(const std::vector<PointCloud>& parts, double voxel_m,
                       const std::function<void(const PointCloud&)>& emit);
// The same over parts that arrive a piece at a time (a tile's PCD read by io::PcdPieceReader):
// next() gives the part's next piece (valid until the following call), null at its end. Memory:
// one piece per part and one output piece.
using PieceSource = std::function<const PointCloud*()>;
void MergeInVoxelOrder(std::vector<PieceSource> parts, double voxel_m, const std::function<void(const PointCloud&)>& emit);
// floor(a / b) for b > 0.
inline std::int64_t FloorDiv(std::int64_t a, std::int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
// A key of an xy cell (32 bits per axis).
inline std::uint64_t PackXY(std::int64_t x, std::int64_t y) {
  return (std::uint64_t(x) << 32) ^ (std::uint64_t(y) & 0xffffffffULL);
}
// The positions (ascending) of the keyframes within radius_m (xy, + one voxel for float rounding)
// of the box: every keyframe within radius_m (3D) of a point in it.
std::vector<std::size_t> KeyframesNear(const std::vector<WorldKeyframe>& kfs, const VoxelBox& box, double voxel_m,
                                       double radius_m);
// The cell (x, y) of a PackXY key.
inline std::pair<std::int64_t, std::int64_t> UnpackXY(std::uint64_t key) {
  return {std::int64_t(std::int32_t(key >> 32)), std::int64_t(std::int32_t(key & 0xffffffffULL))};
}
// [map voxels] The largest tile edge: tiles.edge_m, or 2 x the keyframes' reach, in whole voxels.
std::int64_t MostEdgeVoxels(const RemovertConfig& cfg);
// The finest tile edge in margins: the margin's area, read by a job but not decided, stays below
// the core's: (e + 2 m)^2 <= 2 e^2 needs e >= 2 m / (sqrt 2 - 1) = 4.83 m, in whole margins 5.
constexpr std::int64_t kFinestEdgeMargins = 5;
// Whether a plan may have this tile edge under `cfg` (one of TileEdgeChoices).
bool IsTileEdgeChoice(const RemovertConfig& cfg, std::int64_t edge_voxels);
// Adds a tile's counts and seconds to *sum.
void AddHdStats(const HdStats& part, HdStats* sum);

// ---- LD tiles (ld_tiles.cpp), shared with the LD tile jobs from files (ld_tile_jobs.cpp)
// The voxels of an LD tile's core + margin (its window).
VoxelBox LdWindowBox(const LdTilePlan& plan, std::size_t tile);
// An LD tile's labels of its window's points (each map's points in the window, in map order);
// those outside the core are kLdOutside. Positions and keyframes: the whole sessions'.
LdLabels LabelTile(const LdTilePlan& plan, std::size_t tile, const PointCloud& central_window,
                   const PointCloud& query_window, const PointCloud& central_positions,
                   const PointCloud& query_positions, const std::vector<WorldKeyframe>& central_keyframes,
                   const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg, int threads);

// ---- the stage's keyframe folders (stage.cpp), shared with the stage from tiles (stage_tiles.cpp)
// The clouds of a pair's keyframe folder, in keyframes.csv's column order.
enum KeyframeCloud : int { kKfStatic = 0, kKfHd, kKfPdStrong, kKfPdWeak, kKfNdStrong, kKfNdWeak };
constexpr int kKeyframeClouds = 6;
inline constexpr const char* kKeyframeCloudNames[kKeyframeClouds] = {"static",    "hd",        "pd_strong",
                                                                     "pd_weak",   "nd_strong", "nd_weak"};
inline constexpr PointClass kKeyframeCloudClasses[kKeyframeClouds] = {
    PointClass::kStatic, PointClass::kHD, PointClass::kPDStrong, PointClass::kPDWeak, PointClass::kNDStrong,
    PointClass::kNDWeak};
// The pair's LD clouds a keyframe cloud is cut from, in order, after the central session's static
// map (kKfStatic) or HD map (kKfHd): the whole stage concatenates them, the stage from tiles
// streams their files (LdCloudFile).
std::vector<PointCloud LdResult::*> KeyframeCloudLd(int cloud);
// The file of one of the pair's LD clouds ("nd_strong.pcd", ...).
std::string LdCloudFile(PointCloud LdResult::*cloud);
// The nearest keyframe (position in `tree`) of every point, and optionally its squared distance.
std::vector<std::uint32_t> NearestKeyframes(const PointCloud& pts, const geometry::KdTree& tree, int threads,
                                            std::vector<float>* sq_dist = nullptr);
// Query keyframes farther than out.new_keyframe_dist_m from every central keyframe.
std::vector<std::uint32_t> FarQueryKeyframes(const std::vector<WorldKeyframe>& ckf,
                                             const std::vector<WorldKeyframe>& qkf, const RemovertConfig& cfg,
                                             int threads);
// The keyframe bucket of a pair's output points (stage.cpp's rule): [0, nc) central keyframes,
// nc + j query keyframe j. Central(): the nearest central keyframe; Pd(): the nearest central or
// far query keyframe, a central one farther than out.assign_radius_m giving way to the nearest
// query keyframe. Point-local: a cloud may be given in pieces.
class KeyframeOwners {
 public:
  KeyframeOwners(const std::vector<WorldKeyframe>& ckf, const std::vector<WorldKeyframe>& qkf,
                 const RemovertConfig& cfg, int threads);
  std::vector<std::uint32_t> Central(const PointCloud& pts) const;
  std::vector<std::uint32_t> Pd(const PointCloud& pd) const;
  // The query keyframes (positions) that become new map keyframes: far ones and those owning PD
  // (owns_pd: per bucket).
  std::vector<int> NewKeyframes(const std::vector<bool>& owns_pd) const;

 private:
  std::size_t nc_;
  std::vector<std::uint32_t> new_q_;
  int threads_;
  float assign_r2_;
  geometry::KdTree central_, query_;
  std::unique_ptr<geometry::KdTree> candidates_;
};
// One cloud of a keyframe folder: file name (without .pcd), world-frame points, class and session.
struct KeyframePart {
  const char* name;
  PointCloud cloud;
  PointClass cls;
  int session;
};
// The parts in the keyframe's local frame as PCDs, and with a class field in classes.ply.
void WriteKeyframeDir(const std::string& dir, const Pose& T_world_sensor, const std::vector<KeyframePart>& parts,
                      const RemovertConfig& cfg);
// A central keyframe's parts (every KeyframeCloud) and a new keyframe's (its PD).
std::vector<KeyframePart> CentralKeyframeParts(std::array<PointCloud, kKeyframeClouds> clouds, int ci, int qi);
std::vector<KeyframePart> NewKeyframeParts(PointCloud pd_strong, PointCloud pd_weak, int qi);
// keyframes.csv: counts[bucket][cloud] for every central keyframe, then the new ones (their PD).
void WriteKeyframesCsv(const std::string& dir, const std::vector<WorldKeyframe>& ckf,
                       const std::vector<WorldKeyframe>& qkf, int ci, int qi,
                       const std::vector<std::array<std::size_t, kKeyframeClouds>>& counts,
                       const std::vector<int>& new_list);

// The files of a pair's LD clouds (the stage's pair folder, an LD tile's part, its merge).
std::vector<std::string> LdPairCloudFiles();
// ---- multi-session cleanup (ld_detection.cpp)
// The sensor's joining gaps {horizontal, vertical} [m] at `range_m` for the residues' clusters:
// ld.residue_gap_m or, farther out, geometry::SampleJoinGaps of the sensor's columns and rows (a
// range beyond sensor.max_range_m counts as that range: the voters' reach, in a tile as in the
// whole). ResidueGapsAt(cfg, sensor.max_range_m).x() is the farthest one hop of a residue's
// cluster reaches in xy (LdTileMarginM).
Eigen::Vector2f ResidueGapsAt(const RemovertConfig& cfg, double range_m);

// Marks in *residue (per point of `c`) the clusters `members` of `c` that are a mover's trail: at
// least two of `own_voters` returned on them, each in pieces shorter than a mover, not counting the
// cluster's bottom that the ground's returns touch (ld_detection.cpp); and those that drove with the
// sensor.
void MarkTrails(const PointCloud& c, const std::vector<std::vector<std::uint32_t>>& members,
                const std::vector<WorldKeyframe>& own_voters, const RemovertConfig& cfg, int threads,
                std::vector<bool>* residue);

// Whether the points `m` of `c`, last returned on by keyframe `last`, drove with the sensor: each of
// the keyframes `before` it (their scans' trees in world coordinates, `scans`) returned on more of
// them at their place relative to the sensor than at their place in the world, and all of them by
// more than chance (ld_detection.cpp).
bool DroveWithTheSensor(const PointCloud& c, const std::vector<std::uint32_t>& m, const WorldKeyframe& last,
                        const std::vector<const WorldKeyframe*>& before,
                        const std::vector<std::shared_ptr<const geometry::KdTree>>& scans, const RemovertConfig& cfg);

// ---- the stage tile by tile from files (stage_tiles.cpp)
// RunRemovertStage's sessions and pairs with tiles.stage: every session's HD tiles and every pair's
// LD tiles run from files under out/.tiles (removed at the end) and merged into the stage's
// folders; the pair's keyframe folders cut from the merged clouds. `cfg`: the sensor resolved (the
// central's); rep->pairs given; fills rep->hd, rep->ld and rep->new_keyframes.
void RunStageFromTiles(const RemovertConfig& cfg, const std::vector<std::string>& session_dirs,
                       const std::vector<std::string>& poses_files, const std::vector<std::string>& names,
                       const std::vector<std::vector<WorldKeyframe>>& kfs, const std::string& out, int threads,
                       StageReport* rep);

}  // namespace ltm::removert::detail
