// ltmapper map: what enters the store (keyframes, deltas, session metadata) and what the store
// reports back (session / keyframe records, integration results, regions, fsck, objects).
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace ltm::map {

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

// The same inputs read while the store integrates them, a chunk of keyframes at a time, so that
// memory holds a chunk and not the session (InitFromDirs / IntegrateFromDirs read LT-removert's
// folders this way). `read` is called once per item, from several threads at once.
struct KeyframeSlot {
  int index = 0;
  Pose T_world_sensor = Pose::Identity();
  std::size_t points = 0;  // the cloud's size, known without reading it (0: no cloud)
};
struct KeyframeSource {
  std::vector<KeyframeSlot> keyframes;
  std::function<PointCloud(std::size_t k)> read;  // keyframes[k]'s cloud
};
struct DeltaSource {
  std::vector<int> keyframes;  // reference keyframe indices with a delta
  std::function<KeyframeDelta(std::size_t k)> read;  // the delta of keyframes[k]
};
// Sources over clouds held in memory (copied item by item as the store asks).
KeyframeSource InMemory(const std::vector<KeyframeInput>& keyframes);
DeltaSource InMemory(const std::vector<KeyframeDelta>& deltas);

struct SessionMeta {
  SessionMeta(std::string name_ = {}, const Pose& anchor_ = Pose::Identity(), std::string params_ = {},
              std::vector<Pose> trajectory_ = {})
      : name(std::move(name_)), anchor(anchor_), params(std::move(params_)), trajectory(std::move(trajectory_)) {}
  std::string name;
  Pose anchor = Pose::Identity();  // the session's anchor A (paper eq. 3)
  std::string params;              // free text recorded with the session (resolved config)
  // Where the session's sensor was: its keyframes' world poses in scan order (LT-SLAM's
  // poses_world.txt), every keyframe, also those that made no map keyframe. Empty: not known (the
  // object rules then take the map keyframes as of the step: Store::Trajectory).
  std::vector<Pose> trajectory;
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

// Receives one part of a streamed map (Store::StreamMapAt and friends).
using PartSink = std::function<void(PointCloud&&)>;

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
  // Ids of the step's objects on the other side of the change that could be this one, moved
  // (sizes agree within the sensor's sampling, far enough apart: objects.cpp CouldHaveMoved),
  // ascending. A move whose list holds its partner alone had no alike alternative; with more, a
  // box cannot tell which alike object went where (LinkMoved took the least total displacement).
  std::vector<int> move_candidates;
  // Unchanged objects of its shape standing within its own length of it in the step's map (a row
  // of parked cars: objects.cpp AlikeIn). An end with one is never paired as moved (LinkMoved):
  // among like objects, one that left and one that came are as likely two as one that moved.
  std::size_t alike_beside = 0;
  // How much longer than its box it may be unseen [m]: past each end of its length, how far the
  // sessions that scanned it never sampled (objects.cpp MeasureHiddenEnds: their lines of sight
  // blocked, or too sparse there), summed over both ends; measured only as far as a move's other
  // end could need (0: not measured). A container seen 89 m out at its corner as an L of 3.0 m of
  // its 6.1 m is a view of the container, not a thing 3 m long.
  double hidden_length_m = 0.0;
  int exists_in = 0;   // session whose scans hold the object (session for PD, reference for ND)
  // Identity across steps (Store::Objects, not stored per step): the rows that are one object, the
  // same thing at one place seen by several steps or a move's two ends, form one track; its id is
  // the lowest row id in it, and track_sessions the sessions any of its rows exists in (ascending).
  int track = -1;
  std::vector<int> track_sessions;
  std::size_t points = 0;
  double confidence = 0.0;  // [0, 1] over its final cloud: objects.cpp Rate(), Confidence()
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();  // axis-aligned box
  // Oriented box: yaw of the longest horizontal axis, centre, size = length, width, height [m].
  Eigen::Vector3d box_center = Eigen::Vector3d::Zero(), size = Eigen::Vector3d::Zero();
  double yaw_rad = 0.0;
  double ground_z = 0.0, height_above_ground = 0.0;  // local ground under it, top above it [m]
  double clearance_m = 0.0;           // lowest point above the ground of its cell [m]
  double range_m = 0.0;               // distance to where it was scanned from (ContextOf: trajectories)
  double observed_fraction = 0.0;     // share of see-through evidence (strong ND / weak PD), of its
                                      // points and of the unobserved surface beside them
  // Appeared: points of the step's own surface its reference never observed within the cluster
  // tolerance, that the step's changes do not hold (new territory's strong PD beside it). Counted
  // in observed_fraction's whole; not stored.
  std::size_t unobserved_beside = 0;
  // The cluster SplitFaces cut it from (a face and the rest: two things that touch), -1 when none:
  // no rule joins two pieces of one cut again (PieceOf, HoldUp); not stored.
  int cut_from = -1;
  double twin_fraction = 0.0;         // share with a change of the other side within the twin radius
  double attached_fraction = 0.0;     // share with an unchanged surface within the cluster tolerance
  double box_seen_fraction = 0.0;     // of what the other session observed in its box: the share seen changed
  std::string rejected;               // why it is not an object ("" = an object)
  PointCloud cloud;  // world frame, cls / session / object set
};
// Summary totals for `ltmapper map log`.
struct StoreTotals {
  std::size_t file_bytes = 0, base_bytes = 0, delta_bytes = 0;
  std::size_t base_points = 0, delta_points = 0;
  std::size_t record_steps = 0, record_bytes = 0;  // derived per-step records (stored objects)
};

}  // namespace ltm::map
