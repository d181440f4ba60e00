// Changes between any two sessions' states of the map by composing the stored deltas (the
// paper's "virtual LD", Table II): no scan is read, no visibility is computed.
#include "ltmapper/map/diff.hpp"

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <chrono>

namespace ltm::map {

namespace {
PointCloud Labelled(PointCloud c, PointClass fallback, int session) {
  if (c.cls.size() != c.size()) c.cls.assign(c.size(), fallback);
  for (auto& k : c.cls)
    if (k != PointClass::kPDStrong && k != PointClass::kPDWeak) k = fallback;
  c.session.assign(c.size(), std::uint16_t(session));
  return c;
}
}  // namespace

MapDiff Diff(const Store& store, int from, int to, const Region& region, int threads) {
  const auto t0 = std::chrono::steady_clock::now();
  const int n = int(store.Sessions().size());
  if (from < 0 || to < 0 || from >= n || to >= n)
    throw Error(store.path() + ": diff between sessions " + std::to_string(from) + " and " + std::to_string(to) +
                ": the store holds sessions 0.." + std::to_string(n - 1));
  if (from == to) throw Error("diff: --from and --to name the same session");
  Region exact = region;
  exact.voxel_m = 0.0;  // match the stored points themselves; the voxel applies to the outputs
  // Only keyframes with a delta between the two steps can differ; a point never moves between
  // keyframes, so each keyframe's two states are compared on their own, on the store's grid.
  PointCloud a, b;
  for (auto& [removed, added] : store.KeyframeChanges(from, to, exact)) {
    a.append(removed);
    b.append(added);
  }
  MapDiff d;
  // Added points keep the strength the step that added them gave (strong / weak PD).
  const PointCloud pd = Labelled(std::move(b), PointClass::kPDStrong, to);
  std::vector<bool> weak(pd.size());
  for (std::size_t i = 0; i < pd.size(); ++i) weak[i] = pd.cls[i] == PointClass::kPDWeak;
  d.pd_weak = pd.select(weak);
  weak.flip();
  d.pd_strong = pd.select(weak);
  d.nd = Labelled(std::move(a), PointClass::kNDStrong, from);
  if (region.voxel_m > 0.0)
    for (PointCloud* c : {&d.pd_strong, &d.pd_weak, &d.nd}) *c = geometry::VoxelDownsample(*c, region.voxel_m, threads);
  d.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return d;
}

Agreement Agree(const PointCloud& got, const PointCloud& want, double radius_m) {
  Agreement a;
  a.got = got.size();
  a.want = want.size();
  auto share = [](const std::vector<bool>& m) {
    std::size_t n = 0;
    for (bool b : m) n += b;
    return m.empty() ? 1.0 : double(n) / double(m.size());
  };
  a.precision = share(geometry::WithinRadius(got, want, radius_m));
  a.recall = share(geometry::WithinRadius(want, got, radius_m));
  return a;
}

PairAgreement CompareWithLdPair(const MapDiff& d, const std::string& pair_dir, double radius_m) {
  auto read = [&](const char* name) { return io::ReadPcd(pair_dir + "/" + name); };
  PointCloud pd_ref = read("pd_strong.pcd"), pd = d.pd_strong;
  pd_ref.append(read("pd_weak.pcd"));
  pd_ref.append(read("pd_unobserved.pcd"));  // new territory enters the map as strong PD
  pd.append(d.pd_weak);
  return {Agree(pd, pd_ref, radius_m), Agree(d.nd, read("nd_strong.pcd"), radius_m)};
}

}  // namespace ltm::map
