// The clouds the viewer serves: level of detail by a growing voxel, and the binary wire format.
#include "internal.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace ltm::view {
namespace {

constexpr char kMagic[4] = {'L', 'T', 'M', 'C'};
constexpr std::uint32_t kVersion = 1;
constexpr std::size_t kHeaderBytes = 16;  // magic, version, count, voxel
// A surface's point count falls with the square of the voxel edge; the margin makes the next try
// fit in one step most of the time, and each retry grows the voxel at least this much.
constexpr double kVoxelMargin = 1.05;
constexpr double kMinVoxelGrowth = 1.25;
static_assert(sizeof(float) == 4, "float32 wire format");

template <class T>
void Put(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));  // x86-64 and aarch64 are little endian (checked in CMake)
  out.append(b, sizeof(T));
}

template <class T>
T Get(const std::string& in, std::size_t at) {
  T v;
  std::memcpy(&v, in.data() + at, sizeof(T));
  return v;
}

}  // namespace

PointCloud CoverageCloud(const map::Store& store, int session) {
  PointCloud out;
  for (const auto& k : store.Keyframes()) {
    if (k.session != session) continue;
    PointCloud c = store.KeyframeCloud(k.id, session);
    c.session.clear();
    c.object.clear();
    geometry::TransformInPlace(c, k.T_world_sensor);
    out.append(c);
  }
  return out;
}

PointCloud LayerCloud(const map::Store& store, Layer layer, int session) {
  switch (layer) {
    case Layer::kAt: return store.MapAt(session);
    case Layer::kLive: return store.Live();
    case Layer::kMeta: return store.Meta();
    case Layer::kChanges: return store.StepChanges(session);
    case Layer::kCoverage: return CoverageCloud(store, session);
  }
  throw Error("view: unknown layer");
}

PointCloud ServedCloud(const map::Store& store, Layer layer, int session, const ViewConfig& cfg,
                       double* voxel_m) {
  ValidateConfig(cfg, "view config");
  if (cfg.max_voxel_m < cfg.base_voxel_m) throw Error("view config: max_voxel_m must be >= base_voxel_m");
  const std::size_t budget = std::size_t(cfg.point_budget);
  const PointCloud raw = LayerCloud(store, layer, session);
  double voxel = cfg.base_voxel_m;
  PointCloud out = raw.empty() ? raw : geometry::VoxelDownsample(raw, voxel, cfg.threads);
  while (out.size() > budget && voxel < cfg.max_voxel_m) {
    const double grow = std::sqrt(double(out.size()) / double(budget)) * kVoxelMargin;
    // A float32 value: the wire header carries the exact voxel the cloud was filtered with.
    voxel = double(float(std::min(cfg.max_voxel_m, voxel * std::max(grow, kMinVoxelGrowth))));
    out = geometry::VoxelDownsample(raw, voxel, cfg.threads);
  }
  if (voxel_m) *voxel_m = voxel;
  return out;
}

std::string EncodeCloud(const PointCloud& cloud, double voxel_m) {
  const std::size_t n = cloud.size();
  if (n > 0xffffffffu) throw Error("view: cloud too large to encode (" + std::to_string(n) + " points)");
  std::string out;
  out.reserve(kHeaderBytes + n * 13);
  out.append(kMagic, 4);
  Put<std::uint32_t>(out, kVersion);
  Put<std::uint32_t>(out, std::uint32_t(n));
  Put<float>(out, float(voxel_m));
  for (const auto& p : cloud.points) Put<float>(out, p.x), Put<float>(out, p.y), Put<float>(out, p.z);
  const bool has_cls = cloud.cls.size() == n;
  for (std::size_t i = 0; i < n; ++i)
    out.push_back(char(has_cls ? std::uint8_t(cloud.cls[i]) : std::uint8_t(PointClass::kUnknown)));
  return out;
}

PointCloud DecodeCloud(const std::string& bytes, double* voxel_m) {
  if (bytes.size() < kHeaderBytes || std::memcmp(bytes.data(), kMagic, 4) != 0)
    throw Error("view cloud: no LTMC header");
  if (Get<std::uint32_t>(bytes, 4) != kVersion)
    throw Error("view cloud: version " + std::to_string(Get<std::uint32_t>(bytes, 4)) + " (expected 1)");
  const std::size_t n = Get<std::uint32_t>(bytes, 8);
  if (bytes.size() != kHeaderBytes + n * 13)
    throw Error("view cloud: " + std::to_string(bytes.size()) + " bytes for " + std::to_string(n) + " points");
  if (voxel_m) *voxel_m = Get<float>(bytes, 12);
  PointCloud c;
  c.points.resize(n);
  c.cls.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t at = kHeaderBytes + 12 * i;
    c.points[i] = {Get<float>(bytes, at), Get<float>(bytes, at + 4), Get<float>(bytes, at + 8), 0.f};
    c.cls[i] = PointClass(std::uint8_t(bytes[kHeaderBytes + 12 * n + i]));
  }
  return c;
}

}  // namespace ltm::view
