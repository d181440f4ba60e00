// ltmapper map: LT-map, the evolving multi-session map (paper "LT-map", "Change Composition",
// "Automatic Parsing of Ephemeral Objects").
//
// One SQLite file NAME.ltmap holds, per map keyframe, its HD-free cloud as of the LATEST session
// (the base) and, per session step, the delta that step applied, both in the keyframe's local
// frame. Composition (paper eq. 4) P ⊙ LD = P − ND + PD; the inverse delta (PD and ND swapped)
// rolls a keyframe back, so the map as of any session is rebuilt from the base without snapshots.
// The store schema, blob format and the reasons for "base = latest" are in README.md here.
// SQLite, zstd and PCL are used only inside the .cpp files.
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/geometry/sensor.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace ltm::map {

struct MapConfig {
  // Store encoding (fixed when the store is created; an existing store keeps its own values).
  double resolution_m = 0.001;   // coordinate quantisation step in the keyframe frame
  double intensity_step = 0.01;  // intensity quantisation step [intensity units]
  int zstd_level = 3;            // blob compression level
  // Integration.
  double nd_match_radius_m = 0.1;        // a keyframe point within this of an ND point is removed
  double new_keyframe_radius_m = 10.0;   // query keyframe with no map keyframe within -> new one
  bool store_weak_nd = false;            // keep weak ND points in deltas (they change nothing)
  // Outputs.
  double meta_carve_radius_m = 0.2;      // meta map: points this close to any strong ND are carved
  double output_voxel_m = 0.1;           // voxel size of written maps (0 = every point)
  // Objects (Euclidean clustering of strong ND and PD per session step; rules in objects.cpp).
  double object_tolerance_m = 0.5;
  int object_min_points = 20;
  int object_max_points = 1000000;
  double object_ground_cell_m = 2.0;     // xy cell for the local ground height (0 = keep ground)
  double object_ground_height_m = 0.25;  // change points this close above the lowest map point
                                         // of their cell are ground, not clustered
  double object_max_extent_m = 0.0;      // clusters with a larger xy box edge are not objects (0 = off)
  double object_min_length_m = 2.0;      // clusters with a shorter longest horizontal edge are not objects
  double object_min_observed_fraction = 0.5;  // appeared: share of weak PD (reference saw the space free)
  double object_min_height_m = 0.5;      // top above the local ground
  double object_max_clearance_m = 1.0;  // lowest point above ground: higher = floating (0 = off)
  double object_sensor_step_deg = 0.0;   // [deg] the sensor's coarser angular sampling step; 0 = from the run's
                                         // sensor model (WithSensorStep: `ltmapper run`, `map objects --session`)
  double object_min_samples = 3.0;       // sensor samples across the cluster's width and height
  double object_flat_sigma_m = 0.05;     // thickness (std along the smallest axis) of a flat patch
  double object_flat_tilt_deg = 20.0;    // flat patches with a normal this close to vertical are ground
  double object_twin_radius_m = 1.0;     // other side's change this close = the same surface, misaligned
  double object_twin_max_fraction = 0.5; // clusters with at least this share of such points are ghosts
  double object_max_attached_fraction = 0.5;  // clusters mostly touching unchanged surfaces are fragments
  double object_merge_inside_fraction = 0.5;  // a cluster this much inside a larger one's box joins it
  double object_moved_size_tol = 0.2;    // relative box-size difference of a moved object's two ends
  double object_moved_min_dist_m = 1.0;  // ends closer than this are one object re-scanned, not moved

  template <class V>
  void Visit(V& v) {
    v("resolution_m", resolution_m, "m", 1e-4, 0.1);
    v("intensity_step", intensity_step, "", 1e-6, 100.0);
    v("zstd_level", zstd_level, "", 1, 19);
    v("nd_match_radius_m", nd_match_radius_m, "m", 1e-4, 5.0);
    v("new_keyframe_radius_m", new_keyframe_radius_m, "m", 0.1, 1000.0);
    v("store_weak_nd", store_weak_nd);
    v("meta_carve_radius_m", meta_carve_radius_m, "m", 0.0, 5.0);
    v("output_voxel_m", output_voxel_m, "m", 0.0, 10.0);
    v("object_tolerance_m", object_tolerance_m, "m", 0.01, 10.0);
    v("object_min_points", object_min_points, "", 1, 100000000);
    v("object_max_points", object_max_points, "", 1, 100000000);
    v("object_ground_cell_m", object_ground_cell_m, "m", 0.0, 100.0);
    v("object_ground_height_m", object_ground_height_m, "m", 0.0, 10.0);
    v("object_max_extent_m", object_max_extent_m, "m", 0.0, 10000.0);
    v("object_min_length_m", object_min_length_m, "m", 0.0, 10000.0);
    v("object_min_observed_fraction", object_min_observed_fraction, "", 0.0, 1.0);
    v("object_min_height_m", object_min_height_m, "m", 0.0, 100.0);
    v("object_max_clearance_m", object_max_clearance_m, "m", 0.0, 100.0);
    v("object_sensor_step_deg", object_sensor_step_deg, "deg", 0.0, 45.0);
    v("object_min_samples", object_min_samples, "", 0.0, 1000.0);
    v("object_flat_sigma_m", object_flat_sigma_m, "m", 0.0, 10.0);
    v("object_flat_tilt_deg", object_flat_tilt_deg, "deg", 0.0, 90.0);
    v("object_twin_radius_m", object_twin_radius_m, "m", 0.0, 100.0);
    v("object_twin_max_fraction", object_twin_max_fraction, "", 0.0, 1.0);
    v("object_max_attached_fraction", object_max_attached_fraction, "", 0.0, 1.0);
    v("object_merge_inside_fraction", object_merge_inside_fraction, "", 0.0, 1.0);
    v("object_moved_size_tol", object_moved_size_tol, "", 0.0, 10.0);
    v("object_moved_min_dist_m", object_moved_min_dist_m, "m", 0.0, 10000.0);
  }
};

// ------------------------------------------------------------------------------------- inputs
// A keyframe entering the map: its world pose and its HD-free cloud in its own (sensor) frame.
struct KeyframeInput {
  int index = 0;  // keyframe index in its session (scan file number)
  Pose T_world_sensor = Pose::Identity();
  PointCloud cloud;
};

// LT-removert's changes at one keyframe of the reference session, in that keyframe's frame.
struct KeyframeDelta {
  int keyframe = 0;  // index of the reference session's keyframe
  PointCloud pd_strong, pd_weak, nd_strong, nd_weak;
};

struct SessionMeta {
  SessionMeta(std::string name_ = {}, const Pose& anchor_ = Pose::Identity(), std::string params_ = {})
      : name(std::move(name_)), anchor(anchor_), params(std::move(params_)) {}
  std::string name;
  Pose anchor = Pose::Identity();  // the session's anchor A (paper eq. 3)
  std::string params;              // free text recorded with the session (resolved config)
};

// ----------------------------------------------------------------------------------- records
struct SessionRecord {
  int order = 0;       // 0 = central
  std::string name;
  int reference = -1;  // session the step's changes were detected against (-1 for the base)
  Pose anchor = Pose::Identity();
  std::string params, integrated_utc;
  std::size_t keyframes_new = 0, keyframes_changed = 0;
  std::size_t pd_strong = 0, pd_weak = 0;  // points added by the step
  std::size_t nd_strong = 0, nd_weak = 0;  // points removed as seen-through / kept as occluded
  std::size_t superseded = 0, restored = 0;  // resampled points swapped when reference != previous
  std::size_t points = 0;  // map points (sum over keyframes) after the step
  std::size_t bytes = 0;   // blob bytes written by the step
};

struct KeyframeRecord {
  int id = 0;
  int session = 0;       // session (order) that created it
  int source_index = 0;  // keyframe index in that session
  Pose T_world_sensor = Pose::Identity();
  std::size_t base_points = 0, base_bytes = 0;
  std::size_t delta_count = 0, delta_bytes = 0;
};

struct IntegrationResult {
  int session = 0;
  std::size_t keyframes_new = 0, keyframes_changed = 0;
  std::size_t pd_strong = 0, pd_weak = 0, nd_strong = 0, nd_weak = 0;
  std::size_t superseded = 0, restored = 0;
  std::size_t points = 0, bytes = 0;
  double seconds = 0.0;
};

// Part of the map to build: everything, or an axis-aligned world box; optional voxel filter.
struct Region {
  bool use_box = false;
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
  double voxel_m = 0.0;  // 0 = keep every point
};

struct FsckReport {
  bool ok = true;
  std::vector<std::string> problems;
  std::size_t sessions = 0, keyframes = 0, blobs = 0, points = 0, bytes = 0;
};

struct MapObject {
  int id = 0;         // stable: order of (step, change, centroid x, y) over the store's objects
  int session = 0;    // step that detected it
  int reference = 0;  // session it was compared against
  PointClass cls = PointClass::kUnknown;  // majority class: kPDStrong, kPDWeak or kNDStrong
  std::string change;  // "appeared" (PD), "disappeared" (strong ND), "moved" (either end of a move)
  int partner = -1;    // moved: id of the other end (same step), else -1
  int exists_in = 0;   // session whose scans hold the object (session for PD, reference for ND)
  std::size_t points = 0;
  double confidence = 0.0;  // [0, 1] see objects.cpp Confidence()
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();  // axis-aligned box
  // Oriented box: yaw of the longest horizontal axis, centre, size = length, width, height [m].
  Eigen::Vector3d box_center = Eigen::Vector3d::Zero(), size = Eigen::Vector3d::Zero();
  double yaw_rad = 0.0;
  double ground_z = 0.0, height_above_ground = 0.0;  // local ground under it, top above it [m]
  double clearance_m = 0.0;           // lowest point above the ground of its cell [m]
  double range_m = 0.0;               // distance to the nearest map keyframe (sensor position)
  double observed_fraction = 0.0;     // share of see-through evidence (strong ND / weak PD)
  double twin_fraction = 0.0;         // share with a change of the other side within the twin radius
  double attached_fraction = 0.0;     // share with an unchanged surface within the cluster tolerance
  std::string rejected;               // why it is not an object ("" = an object)
  PointCloud cloud;  // world frame, cls / session / object set
};
// Summary totals for `ltmapper map log`.
struct StoreTotals {
  std::size_t file_bytes = 0, base_bytes = 0, delta_bytes = 0;
  std::size_t base_points = 0, delta_points = 0;
};

// ------------------------------------------------------------------------------------- store
class Store {
 public:
  // Creates a new store file (error when `path` exists). Encoding values come from `cfg`.
  static Store Create(const std::string& path, const MapConfig& cfg);
  // kReadOnly: SQLITE_OPEN_READONLY, no journal mode switch, nothing written or created (works on
  // read-only media and on another user's store); integrating through such a store fails.
  enum class Access { kReadWrite, kReadOnly };
  // Opens an existing store; checks the schema version. Integration parameters come from `cfg`,
  // the encoding (resolution, intensity step) from the store.
  static Store Open(const std::string& path, const MapConfig& cfg = {}, Access access = Access::kReadWrite);
  Store(Store&&) noexcept;
  Store& operator=(Store&&) noexcept;
  ~Store();

  const std::string& path() const;
  const MapConfig& config() const;  // encoding fields as stored
  void set_threads(int threads);    // 0 = all cores

  // The central session: every keyframe becomes a map keyframe. One transaction.
  IntegrationResult IntegrateBase(const SessionMeta& session, const std::vector<KeyframeInput>& keyframes);
  // A query session's changes against `reference` (an integrated session, usually the central
  // one): per reference keyframe with a delta, the keyframe's state becomes reference-state − ND
  // + PD. `query_keyframes` carry this session's points that no reference keyframe owns (LT-
  // removert's new_keyframes/: PD in new territory; cls array optional, default kPDStrong): one
  // with no map keyframe within new_keyframe_radius_m becomes a new map keyframe (its cloud is the
  // base); otherwise its points join the nearest map keyframe's target (a keyframe created by an
  // earlier query is replaced by what this session saw there). Keyframes without any input keep
  // their latest state. One transaction (BEGIN IMMEDIATE ... COMMIT): an exception or a kill
  // leaves the previous state.
  IntegrationResult IntegrateSession(const SessionMeta& session, const std::string& reference,
                                     const std::vector<KeyframeDelta>& deltas,
                                     const std::vector<KeyframeInput>& query_keyframes);
  // Test hook: called inside the integration transaction after each keyframe is written.
  std::function<void(std::size_t keyframes_written)> on_keyframe_written;

  std::vector<SessionRecord> Sessions() const;
  std::vector<KeyframeRecord> Keyframes() const;
  int SessionOrder(const std::string& name) const;  // throws when unknown
  int LatestSession() const;                        // -1 when empty
  StoreTotals Totals() const;

  // One keyframe as of `session` (local frame; cls and session arrays set); empty when the
  // keyframe did not exist yet.
  PointCloud KeyframeCloud(int keyframe_id, int session) const;
  // The map as of `session` in the world frame (restore by chained inverse deltas).
  PointCloud MapAt(int session, const Region& region = {}) const;
  PointCloud Live(const Region& region = {}) const;  // latest state, all PD
  // What differs between the states as of sessions `a` and `b`, per keyframe with a delta between
  // them (or created between them): (points of a's state with no point of b's within one grid
  // step, the reverse), world frame. Every other keyframe is the same in both and is neither
  // decoded nor returned (map::Diff).
  std::vector<std::pair<PointCloud, PointCloud>> KeyframeChanges(int a, int b, const Region& region = {}) const;
  // Meta map: the first state of every keyframe plus strong PD of every later step, minus
  // everything within meta_carve_radius_m of any point a step removed as seen-through (strong ND).
  PointCloud Meta(const Region& region = {}) const;
  // The changes of one step in the world frame: PD strong/weak (added), ND strong (removed),
  // ND weak (kept), plus the weak PD of the keyframes the step created (new territory).
  // cls set, session = the step.
  PointCloud StepChanges(int session, const Region& region = {}) const;
  // Objects a user can act on (objects.cpp): Euclidean clusters (PCL) of each step's strong ND
  // and PD above the local ground, kept only in space both sessions observed and when they pass
  // the geometric rules; moved pairs linked. `rejected` (optional) receives the other clusters
  // with the reason.
  std::vector<MapObject> Objects(std::vector<MapObject>* rejected = nullptr) const;  // needs object_sensor_step_deg > 0

  // Schema version, PRAGMA integrity_check, foreign keys, every blob's checksum and decoding,
  // references between rows, and that every stored base equals its deltas' composition counts.
  FsckReport Fsck() const;
  // Hash of all logical content (sessions, keyframes, blobs); equal stores give equal digests.
  std::uint64_t Digest() const;

  struct Impl;  // opaque (SQLite handle); public only so store.cpp helpers can name it

 private:
  explicit Store(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// ------------------------------------------------------------------------------------- diff
// What changed between the map as of session `from` and as of session `to` (any two, either
// order), from the stored deltas alone (the paper's virtual LD): PD = points of the `to` state
// the `from` state lacks (strong / weak as the step that added them said), ND = points of the
// `from` state the `to` state lacks (removed as seen through). Weak ND are not changes of the
// map (they stay in it) and are not stored by default (store_weak_nd), so they are not listed.
// cls and session set (session = the state the point is in).
struct MapDiff {
  PointCloud pd_strong, pd_weak, nd;
  double seconds = 0.0;
};
MapDiff Diff(const Store& store, int from, int to, const Region& region = {}, int threads = 0);
// Point-wise agreement of `got` with `want`: precision = share of `got` points with a `want`
// point within radius_m, recall = share of `want` points with a `got` point within radius_m.
struct Agreement {
  std::size_t got = 0, want = 0;
  double precision = 0.0, recall = 0.0;
};
Agreement Agree(const PointCloud& got, const PointCloud& want, double radius_m);
// A diff against an LT-removert pair folder of the same two sessions: PD (strong + weak) against
// the pair's pd_strong + pd_weak + pd_unobserved (new territory enters the map as strong PD), ND
// against its nd_strong.
struct PairAgreement {
  Agreement pd, nd;
};
PairAgreement CompareWithLdPair(const MapDiff& diff, const std::string& pair_dir, double radius_m);

// ------------------------------------------------------------------------------- composition
// Mask of `cloud` points within `radius_m` of any point of `query` (spatial hash).
std::vector<bool> WithinRadius(const PointCloud& cloud, const PointCloud& query, double radius_m);

// --------------------------------------------------------------------------------------- blobs
// The store's blob codec on a cloud (cls / session arrays kept when present): coordinates
// quantised to `resolution_m` (error <= resolution/2), intensity to `intensity_step`, zstd, and an
// FNV-1a 64 checksum verified by DecodeBlob (ltm::Error naming `what` on any mismatch).
std::string EncodeBlob(const PointCloud& cloud, double resolution_m, double intensity_step,
                       int zstd_level = 3);
PointCloud DecodeBlob(const std::string& blob, const std::string& what = "blob");

// ------------------------------------------------------------------------------- file layer
// Reads LT-SLAM (aligned/<s>/poses_world.txt, anchor.txt) and LT-removert (changes/pair_<c>_<q>/
// keyframes/NNNNNN/*.pcd, changes/<s>/static_map.pcd) outputs as in docs/FORMATS.md.
struct PipelineDirs {
  std::string aligned;   // LT-SLAM output
  std::string changes;   // LT-removert output
  std::string sessions;  // optional: input session dirs (maps keyframe index -> pose line)
};
// Aligned session names in run order, from the run manifest (io::ReadRunManifest); without a
// manifest (folders made by hand), the aligned folders sorted by name, `central` moved first.
// With a manifest, a `central` other than the run's first session is an error.
std::vector<std::string> AlignedSessions(const PipelineDirs& dirs, const std::string& central = "");
// Creates `store_path` atomically (temporary file, then rename) with the central session as base.
IntegrationResult InitFromDirs(const std::string& store_path, const MapConfig& cfg,
                               const PipelineDirs& dirs, const std::string& central, int threads = 0);
// Integrates one query session from the pair directory central -> query.
IntegrationResult IntegrateFromDirs(Store& store, const PipelineDirs& dirs, const std::string& query);

// ------------------------------------------------------------------------------------ outputs
// Writes .pcd (x y z intensity class session object fields) or .ply by extension, atomically.
void WriteLabelledCloud(const std::string& path, const PointCloud& cloud);
// objects.csv, objects.json, objects.ply (all points with object ids), clouds/object_NNNN.pcd.
// With `rejected`, also rejected.csv (same columns plus `reason`, no clouds).
// The config with object_sensor_step_deg taken from the sensor when it is 0: the beam spacing at
// the horizon (where a vehicle sees objects) or the azimuth step, whichever is coarser.
MapConfig WithSensorStep(MapConfig cfg, const geometry::SensorModel& sensor);
void WriteObjects(const std::string& dir, const std::vector<MapObject>& objects,
                  const std::vector<MapObject>* rejected = nullptr);
// Human-readable `log` table.
std::string FormatLog(const Store& store);

}  // namespace ltm::map
