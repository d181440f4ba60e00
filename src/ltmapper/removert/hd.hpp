// ltmapper removert: HD removal (remove-then-revert) of one session.
#pragma once

#include "ltmapper/removert/keyframes.hpp"

#include <vector>

namespace ltm::removert {

struct HdStats {
  std::size_t map_points = 0;
  std::vector<std::size_t> removed_per_resolution;  // candidates found at each removal resolution
  std::size_t candidates = 0;   // union over the removal resolutions
  std::size_t reverted = 0;
  std::size_t removed = 0;      // candidates - reverted
  std::size_t dilated = 0;      // further points within hd.dilate_voxels map voxels of a removed point
  double seconds_map = 0, seconds_votes = 0;
};
struct HdResult {
  PointCloud static_map;  // world frame, HD-free
  PointCloud hd_map;      // world frame, removed points
  HdStats stats;
};
// The session map: union of the keyframe scans in the world frame (range-filtered), voxel
// downsampled; built in batches of keyframes merged as a binary tree over the batches, so only a
// few scans are in memory at once and a tile's map (tiles.hpp) has the same voxels, bit for bit.
PointCloud BuildSessionMap(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                           int threads = 0);
// HD removal of one session (builds its map first).
HdResult RemoveHd(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                  int threads = 0);
// HD removal of a given map (world frame) against the keyframes.
HdResult RemoveHdFromMap(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes,
                         const RemovertConfig& cfg, int threads = 0);

}  // namespace ltm::removert
