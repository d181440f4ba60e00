// Automatic parsing of ephemeral objects (paper sec. "Automatic Parsing of Ephemeral Objects"):
// Euclidean clustering (PCL) of each step's PD (strong and weak) and strong ND points.
#include "ltmapper/map/map.hpp"

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/segmentation/extract_clusters.h>

#include <cmath>
#include <map>
#include <unordered_map>

namespace ltm::map {
namespace {

struct CellKey {
  std::int64_t x, y;
  bool operator==(const CellKey& o) const { return x == o.x && y == o.y; }
};
struct CellKeyHash {
  std::size_t operator()(const CellKey& c) const { return std::size_t(c.x * 73856093) ^ std::size_t(c.y * 19349663); }
};
using Floor = std::unordered_map<CellKey, float, CellKeyHash>;

CellKey KeyOf(const PointXYZI& p, double cell) {
  return {std::int64_t(std::floor(double(p.x) / cell)), std::int64_t(std::floor(double(p.y) / cell))};
}
void Lower(Floor& floor, const PointCloud& c, double cell) {
  for (const auto& p : c.points) {
    auto [it, added] = floor.emplace(KeyOf(p, cell), p.z);
    if (!added) it->second = std::min(it->second, p.z);
  }
}

}  // namespace

std::vector<MapObject> Store::Objects() const {
  const MapConfig& cfg = config();
  std::vector<MapObject> out;
  const auto sessions = Sessions();
  for (std::size_t S = 1; S < sessions.size(); ++S) {
    const PointCloud changes = StepChanges(int(S));
    // Local ground: lowest point per xy cell of the maps before and after the step and of the
    // changes; change points just above it are ground patches, not objects.
    std::vector<bool> ground(changes.size(), false);
    if (cfg.object_ground_cell_m > 0.0 && !changes.empty()) {
      Floor floor;
      Lower(floor, MapAt(int(S) - 1), cfg.object_ground_cell_m);
      Lower(floor, MapAt(int(S)), cfg.object_ground_cell_m);
      Lower(floor, changes, cfg.object_ground_cell_m);
      for (std::size_t i = 0; i < changes.size(); ++i)
        ground[i] = changes.points[i].z <= floor.at(KeyOf(changes.points[i], cfg.object_ground_cell_m)) +
                                               float(cfg.object_ground_height_m);
    }
    for (int group = 0; group < 2; ++group) {  // 0: PD (strong + weak), 1: strong ND
      std::vector<std::uint32_t> idx;
      for (std::size_t i = 0; i < changes.size(); ++i) {
        const PointClass c = changes.cls[i];
        const bool pd = c == PointClass::kPDStrong || c == PointClass::kPDWeak;
        if (ground[i]) continue;
        if ((group == 0 && pd) || (group == 1 && c == PointClass::kNDStrong)) idx.push_back(std::uint32_t(i));
      }
      if (idx.size() < std::size_t(cfg.object_min_points)) continue;
      pcl::PointCloud<pcl::PointXYZ>::Ptr pc(new pcl::PointCloud<pcl::PointXYZ>);
      pc->reserve(idx.size());
      for (auto i : idx) pc->push_back(pcl::PointXYZ(changes.points[i].x, changes.points[i].y, changes.points[i].z));
      pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
      tree->setInputCloud(pc);
      std::vector<pcl::PointIndices> clusters;
      pcl::EuclideanClusterExtraction<pcl::PointXYZ> ec;
      ec.setClusterTolerance(cfg.object_tolerance_m);
      ec.setMinClusterSize(cfg.object_min_points);
      ec.setMaxClusterSize(cfg.object_max_points);
      ec.setSearchMethod(tree);
      ec.setInputCloud(pc);
      ec.extract(clusters);
      for (const auto& cl : clusters) {
        MapObject o;
        o.id = int(out.size());
        o.session = int(S);
        o.reference = sessions[S].reference;
        std::vector<std::uint32_t> sel;
        for (int j : cl.indices) sel.push_back(idx[std::size_t(j)]);
        o.cloud = changes.select(sel);
        o.cloud.object.assign(o.cloud.size(), o.id);
        o.points = o.cloud.size();
        std::map<PointClass, std::size_t> votes;
        o.lo = o.hi = o.cloud.points[0].xyz().cast<double>();
        for (std::size_t i = 0; i < o.cloud.size(); ++i) {
          const Eigen::Vector3d p = o.cloud.points[i].xyz().cast<double>();
          o.centroid += p;
          o.lo = o.lo.cwiseMin(p);
          o.hi = o.hi.cwiseMax(p);
          ++votes[o.cloud.cls[i]];
        }
        o.centroid /= double(o.points);
        const Eigen::Vector3d ext = o.hi - o.lo;
        if (cfg.object_max_extent_m > 0.0 && std::max(ext.x(), ext.y()) > cfg.object_max_extent_m) continue;
        std::size_t best = 0;
        for (const auto& [c, n] : votes)
          if (n > best) best = n, o.cls = c;
        out.push_back(std::move(o));
      }
    }
  }
  return out;
}

}  // namespace ltm::map
