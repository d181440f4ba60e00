// Private to src/ltmapper/map: quantised clouds, blob codec and the integer-key composition.
#pragma once

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/map/map.hpp"

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace ltm::map::detail {

// Keyframes decoded, read or stepped at a time (streamed maps, integration, objects): enough for
// every worker to have several, few enough that a batch is a small part of any large map.
constexpr std::size_t kKeyframesPerBatch = 64;

// Role of a point inside a stored delta (a state point always has kAdded).
enum Role : std::uint8_t {
  kAdded = 0,               // appended by the step (PD, or a point the reference state had)
  kRemovedChange = 1,       // removed: matched a strong ND (seen through)
  kRemovedSuperseded = 2,   // removed: not in the step's target state (resampled / reverted)
  kInfoNDWeak = 3,          // weak ND: kept in the map, recorded for objects / export
};

// A point on the store's grid: coordinates in units of resolution_m in the keyframe frame,
// intensity in units of intensity_step. cls / session travel with the point through compositions.
struct QPoint {
  std::int32_t x = 0, y = 0, z = 0, i = 0;
  std::uint16_t session = 0;
  std::uint8_t cls = 0;
  std::uint8_t role = kAdded;
};
using QCloud = std::vector<QPoint>;

// Coordinates are packed into 21-bit signed fields for the composition key: |q| < 2^20.
constexpr std::int32_t kMaxCoord = (1 << 20) - 1;

inline std::uint64_t Key(const QPoint& p) {
  constexpr std::uint64_t m = (1ull << 21) - 1;
  return ((std::uint64_t(std::uint32_t(p.x)) & m) << 42) | ((std::uint64_t(std::uint32_t(p.y)) & m) << 21) |
         (std::uint64_t(std::uint32_t(p.z)) & m);
}

// The composition key set (geometry::KeySet: the keys above never have all bits set).
using geometry::KeySet;

// Throws ltm::Error (naming `what` and the point) for non-finite or out-of-range points.
QCloud Quantize(const PointCloud& cloud, double resolution_m, double intensity_step,
                PointClass default_cls, std::uint16_t default_session, const std::string& what);
PointCloud Dequantize(const QCloud& q, double resolution_m, double intensity_step);

std::string EncodeQ(const QCloud& q, double resolution_m, double intensity_step, int zstd_level);
// Verifies the checksum and the sizes; returns the points and the blob's resolution / step.
QCloud DecodeQ(const void* data, std::size_t size, const std::string& what, double* resolution_m = nullptr,
               double* intensity_step = nullptr);
// FNV-1a 64 offset basis (the hash of no bytes).
constexpr std::uint64_t kFnvOffsetBasis = 14695981039346656037ull;
std::uint64_t Fnv1a64(const void* data, std::size_t size, std::uint64_t h = kFnvOffsetBasis);

// Bytes compressed (zstd) behind a header with the raw size and an FNV-1a 64 checksum of the
// payload: the store's derived records (the per-step object cache). Unpack verifies both before
// it allocates, and throws ltm::Error naming `what`.
std::string PackBytes(const std::string& raw, int zstd_level);
std::string UnpackBytes(const void* data, std::size_t size, const std::string& what);

// One step's objects and rejected clusters as bytes (object_codec.cpp), for the store's cache.
std::string EncodeObjects(const std::vector<MapObject>& kept, const std::vector<MapObject>& rejected);
void DecodeObjects(const std::string& raw, const std::string& what, std::vector<MapObject>* kept,
                   std::vector<MapObject>* rejected);

// ---- composition on the grid (exact: stored ND are copies of the points they remove)
// Forward: drop every state point whose key is a removed key of `delta`, append kAdded points.
QCloud ApplyForward(const QCloud& state, const QCloud& delta);
// Inverse (PD and ND swapped): drop every state point whose key an added point has, re-append
// the removed points.
QCloud ApplyInverse(const QCloud& state, const QCloud& delta);
// Delta taking `latest` to `target`: keys of latest absent from target are removed (role
// kRemovedChange when in `change_keys`, else kRemovedSuperseded), keys of target absent from
// latest are added; `info` points are appended with kInfoNDWeak. Shared keys keep latest's points.
QCloud MakeDelta(const QCloud& latest, const QCloud& target, const KeySet& change_keys,
                 const QCloud& info);
// Points of `cloud` with no point of `other` within one grid step (the same cell or one of its
// six face neighbours: the integer offsets of length <= 1).
QCloud Unmatched(const QCloud& cloud, const QCloud& other);
// Mask of `cloud` points within `radius_units` (grid units) of any `query` point.
std::vector<bool> WithinRadiusQ(const QCloud& cloud, const QCloud& query, double radius_units);

// Pairs (row, column) of a cost matrix (cost[row][column], every row the same length), each row
// and column in at most one pair: as many pairs as the allowed costs (finite) permit, and of
// those the least total cost. Forbidden pairs: non-finite costs. Sorted by row. (assignment.cpp)
std::vector<std::pair<std::size_t, std::size_t>> LeastCostPairs(const std::vector<std::vector<double>>& cost);

// Change classes as the objects read them (objects.cpp, object_shape.cpp, object_identity.cpp): PD, either
// strength; weak ND, an object's unseen parts (UnseenParts), not something seen.
inline bool IsPd(PointClass c) { return c == PointClass::kPDStrong || c == PointClass::kPDWeak; }
inline bool Unseen(PointClass c) { return c == PointClass::kNDWeak; }
// The points of an object's cloud that the sessions sampled (SeenPoints), or its unseen parts
// (UnseenPoints).
inline PointCloud PointsWithUnseen(const PointCloud& c, bool unseen) {
  std::vector<std::uint32_t> idx;
  for (std::size_t i = 0; i < c.size(); ++i)
    if (Unseen(c.cls[i]) == unseen) idx.push_back(std::uint32_t(i));
  return c.select(idx);
}
inline PointCloud SeenPoints(const PointCloud& c) { return PointsWithUnseen(c, false); }
inline PointCloud UnseenPoints(const PointCloud& c) { return PointsWithUnseen(c, true); }
// A change the other session saw through its place (strong ND, weak PD): see-through evidence.
inline bool SeenThrough(PointClass c) { return c == PointClass::kNDStrong || c == PointClass::kPDWeak; }

// Disappeared object d and appeared object a could be one object that moved (objects.cpp).
bool CouldHaveMoved(const MapObject& d, const MapObject& a, const MapConfig& cfg);

// Identity across steps of the store's objects, all steps' rows in `objects` (object_identity.cpp):
// those that confirm an earlier step's object go to `rejected` ("reported"); then stable ids, moves
// linked, tracks, and the moves later steps' views inherit.
void IdentifyAcrossSteps(std::vector<MapObject>& objects, std::vector<MapObject>& rejected, const MapConfig& cfg);

}  // namespace ltm::map::detail
