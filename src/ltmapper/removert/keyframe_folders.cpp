// A pair's keyframe folders (stage.cpp's keyframe assignment rule), shared by the whole stage and
// the stage from tiles (stage_tiles.cpp): which keyframe owns each output point, the folders'
// clouds in the keyframe's local frame, keyframes.csv.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/io/io.hpp"

#include <iomanip>

namespace ltm::removert {
namespace {

PointCloud Voxel(const PointCloud& c, double voxel_m) {
  return voxel_m > 0.0 ? geometry::VoxelDownsample(c, voxel_m, 1) : c;
}

}  // namespace

std::vector<PointCloud LdResult::*> detail::KeyframeCloudLd(int cloud) {
  switch (cloud) {
    case kKfStatic: return {};
    case kKfHd: return {&LdResult::nd_residue};  // the residues of movers the query saw through
    case kKfPdStrong: return {&LdResult::pd_strong, &LdResult::pd_unobserved};  // new territory like strong PD
    case kKfPdWeak: return {&LdResult::pd_weak};
    case kKfNdStrong: return {&LdResult::nd_strong};
    default: return {&LdResult::nd_weak};
  }
}

std::vector<std::uint32_t> detail::NearestKeyframes(const PointCloud& pts, const geometry::KdTree& tree, int threads,
                                                    std::vector<float>* sq_dist) {
  std::vector<std::uint32_t> out(pts.size(), 0);
  if (sq_dist) sq_dist->assign(pts.size(), 0.f);
  const std::size_t chunk = 8192;
  detail::ParallelFor((pts.size() + chunk - 1) / chunk, threads, [&](std::size_t c) {
    const std::size_t b = c * chunk, e = std::min(pts.size(), b + chunk);
    for (std::size_t i = b; i < e; ++i) {
      std::uint32_t k = 0;
      float d2 = 0.f;
      tree.Nearest(pts.points[i].xyz(), &k, &d2);
      out[i] = k;
      if (sq_dist) (*sq_dist)[i] = d2;
    }
  });
  return out;
}

void detail::WriteKeyframeDir(const std::string& dir, const Pose& T_world_sensor, const std::vector<KeyframePart>& parts,
                      const RemovertConfig& cfg) {
  io::MakeDirs(dir);
  std::vector<PointCloud> local(parts.size());
  std::vector<io::PlyPart> ply;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    local[p] = Voxel(detail::ToLocal(parts[p].cloud, T_world_sensor), cfg.keyframe_voxel_m);
    io::WritePcd(dir + "/" + parts[p].name + ".pcd", local[p]);
    ply.push_back({&local[p], parts[p].cls, std::uint16_t(parts[p].session)});
  }
  if (cfg.write_ply) io::WritePly(dir + "/classes.ply", ply);
}

std::vector<detail::KeyframePart> detail::CentralKeyframeParts(std::array<PointCloud, kKeyframeClouds> clouds, int ci,
                                                               int qi) {
  std::vector<KeyframePart> parts;
  for (int c = 0; c < kKeyframeClouds; ++c)
    parts.push_back({kKeyframeCloudNames[c], std::move(clouds[std::size_t(c)]), kKeyframeCloudClasses[c],
                     c == kKfPdStrong || c == kKfPdWeak ? qi : ci});
  return parts;
}

std::vector<detail::KeyframePart> detail::NewKeyframeParts(PointCloud pd_strong, PointCloud pd_weak, int qi) {
  return {{kKeyframeCloudNames[kKfPdStrong], std::move(pd_strong), PointClass::kPDStrong, qi},
          {kKeyframeCloudNames[kKfPdWeak], std::move(pd_weak), PointClass::kPDWeak, qi}};
}

std::vector<std::uint32_t> detail::FarQueryKeyframes(const std::vector<WorldKeyframe>& ckf,
                                                     const std::vector<WorldKeyframe>& qkf, const RemovertConfig& cfg,
                                                     int threads) {
  std::vector<float> qd2;
  NearestKeyframes(Positions(qkf), geometry::KdTree(Positions(ckf)), threads, &qd2);
  std::vector<std::uint32_t> far;
  const float nk2 = float(cfg.new_keyframe_dist_m * cfg.new_keyframe_dist_m);
  for (std::size_t j = 0; j < qkf.size(); ++j)
    if (qd2[j] > nk2) far.push_back(std::uint32_t(j));
  return far;
}

detail::KeyframeOwners::KeyframeOwners(const std::vector<WorldKeyframe>& ckf, const std::vector<WorldKeyframe>& qkf,
                                       const RemovertConfig& cfg, int threads)
    : nc_(ckf.size()), new_q_(FarQueryKeyframes(ckf, qkf, cfg, threads)), threads_(threads),
      assign_r2_(float(cfg.assign_radius_m * cfg.assign_radius_m)), central_(Positions(ckf)), query_(Positions(qkf)) {
  PointCloud cand = Positions(ckf);
  const PointCloud query = Positions(qkf);
  for (auto j : new_q_) cand.points.push_back(query.points[j]);
  candidates_ = std::make_unique<geometry::KdTree>(std::move(cand));
}

std::vector<std::uint32_t> detail::KeyframeOwners::Central(const PointCloud& pts) const {
  return NearestKeyframes(pts, central_, threads_);
}

std::vector<std::uint32_t> detail::KeyframeOwners::Pd(const PointCloud& pd) const {
  std::vector<float> d2;
  std::vector<std::uint32_t> owner = NearestKeyframes(pd, *candidates_, threads_, &d2);
  for (std::size_t i = 0; i < pd.size(); ++i) {
    std::uint32_t& o = owner[i];
    if (o >= nc_) {
      o = std::uint32_t(nc_) + new_q_[o - nc_];
    } else if (d2[i] > assign_r2_) {
      std::uint32_t j = 0;
      float dq = 0.f;
      query_.Nearest(pd.points[i].xyz(), &j, &dq);
      o = std::uint32_t(nc_) + j;
    }
  }
  return owner;
}

std::vector<int> detail::KeyframeOwners::NewKeyframes(const std::vector<bool>& owns_pd) const {
  std::vector<bool> is_new(owns_pd.size() - nc_, false);
  for (std::size_t j = 0; j < is_new.size(); ++j) is_new[j] = owns_pd[nc_ + j];
  for (auto j : new_q_) is_new[j] = true;
  std::vector<int> list;
  for (std::size_t j = 0; j < is_new.size(); ++j)
    if (is_new[j]) list.push_back(int(j));
  return list;
}

void detail::WriteKeyframesCsv(const std::string& dir, const std::vector<WorldKeyframe>& ckf,
                               const std::vector<WorldKeyframe>& qkf, int ci, int qi,
                               const std::vector<std::array<std::size_t, kKeyframeClouds>>& counts,
                               const std::vector<int>& new_list) {
  io::WriteFileAtomic(dir + "/keyframes.csv", [&](std::ostream& os) {
    os << "kind,session,index";
    for (const char* name : kKeyframeCloudNames) os << ',' << name;
    os << ",r00,r01,r02,tx,r10,r11,r12,ty,r20,r21,r22,tz\n";
    os << std::setprecision(9);
    auto row = [&](const char* kind, int ses, const WorldKeyframe& kf, const std::array<std::size_t, kKeyframeClouds>& n) {
      os << kind << ',' << ses << ',' << kf.index;
      for (std::size_t c : n) os << ',' << c;
      const Eigen::Matrix4d M = kf.T_world_sensor.matrix();
      for (int r = 0; r < 3; ++r)
        for (int cc = 0; cc < 4; ++cc) os << ',' << M(r, cc);
      os << '\n';
    };
    for (std::size_t k = 0; k < ckf.size(); ++k) row("central", ci, ckf[k], counts[k]);
    for (int j : new_list) {
      std::array<std::size_t, kKeyframeClouds> n{};
      n[kKfPdStrong] = counts[ckf.size() + std::size_t(j)][kKfPdStrong];
      n[kKfPdWeak] = counts[ckf.size() + std::size_t(j)][kKfPdWeak];
      row("new", qi, qkf[std::size_t(j)], n);
    }
  });
}

}  // namespace ltm::removert
