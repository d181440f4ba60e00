// Embree 3 scenes and the spinning LiDAR. One instanced scene per part: the permanent world,
// each LD object, and two actor prototypes; each session has a top-level scene instancing the
// permanent world, its LD objects and its moving actors (re-committed per keyframe, which only
// rebuilds the small instance BVH).
#include "ltmapper/sim/internal.hpp"

#include <embree3/rtcore.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>

namespace ltm::sim {

namespace {

struct InstanceKind {
  enum Type { kPermanent, kLd, kActor } type = kPermanent;
  int index = 0;  // LD object index or actor index in the session plan
};

struct SessionScene {
  RTCScene top = nullptr;
  std::vector<InstanceKind> inst;      // by instance geometry id in `top`
  std::vector<RTCGeometry> actor_geom; // by actor index
  std::vector<bool> actor_on;
  std::vector<Eigen::Matrix3f> actor_rot;
  int keyframe = -2;
};

void ErrorCallback(void* user, RTCError code, const char* str) {
  auto* msg = static_cast<std::string*>(user);
  static std::mutex m;
  std::lock_guard<std::mutex> lock(m);
  if (msg->empty()) *msg = "Embree error " + std::to_string(int(code)) + ": " + (str ? str : "");
}

}  // namespace

struct Simulator::Impl {
  detail::Scenario sc;
  int threads = 0;
  tbb::task_arena arena;  // bounds Embree's BVH builds; the ray loops take `threads` (ParallelForChunks)
  std::string embree_error;
  RTCDevice device = nullptr;
  RTCScene permanent = nullptr, car = nullptr, pedestrian = nullptr;
  std::vector<RTCScene> ld;
  std::vector<SessionScene> sessions;
  std::vector<Eigen::Vector3f> dirs;  // sensor-frame ray directions, beam-major
  std::size_t triangles = 0;
  std::vector<LdObjectInfo> ld_info;

  Impl(const SimConfig& cfg, int n_threads)
      : sc(detail::BuildScenario(cfg)),
        threads(n_threads),
        arena(n_threads > 0 ? n_threads : tbb::task_arena::automatic) {
    const std::string config = n_threads > 0 ? "threads=" + std::to_string(n_threads) : "";
    device = rtcNewDevice(config.empty() ? nullptr : config.c_str());
    if (!device) throw Error("sim: cannot create the Embree device (error " + std::to_string(int(rtcGetDeviceError(nullptr))) + ")");
    rtcSetDeviceErrorFunction(device, ErrorCallback, &embree_error);
    for (const auto& o : sc.ld) ld_info.push_back(o.info);
    arena.execute([&] { Build(); });
    Check("building the scenes");
    const int B = sc.cfg.beams, C = sc.cfg.columns;
    dirs.resize(std::size_t(B) * C);
    const std::vector<double> elevations = BeamElevationsDeg(sc.cfg);
    for (int b = 0; b < B; ++b) {
      const double el = elevations[std::size_t(b)] * M_PI / 180.0;
      for (int c = 0; c < C; ++c) {
        // Column 0 at azimuth +180 deg, azimuth decreasing with the column (geometry::RangeImage).
        const double az = M_PI - 2.0 * M_PI * c / C;
        dirs[std::size_t(b) * C + c] = Eigen::Vector3f(float(std::cos(el) * std::cos(az)),
                                                       float(std::cos(el) * std::sin(az)), float(std::sin(el)));
      }
    }
  }

  ~Impl() {
    for (auto& s : sessions) {
      if (s.top) rtcReleaseScene(s.top);
    }
    for (auto* s : ld) rtcReleaseScene(s);
    if (permanent) rtcReleaseScene(permanent);
    if (car) rtcReleaseScene(car);
    if (pedestrian) rtcReleaseScene(pedestrian);
    if (device) rtcReleaseDevice(device);
  }

  void Check(const std::string& what) {
    if (!embree_error.empty()) throw Error("sim: " + what + ": " + embree_error);
  }

  RTCScene MeshScene(const detail::Mesh& m, RTCBuildQuality quality) {
    RTCScene scene = rtcNewScene(device);
    rtcSetSceneBuildQuality(scene, quality);
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                          3 * sizeof(float), m.v.size()));
    auto* f = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                             3 * sizeof(unsigned), m.f.size()));
    if (!v || !f) throw Error("sim: Embree could not allocate a geometry buffer");
    for (std::size_t i = 0; i < m.v.size(); ++i) {
      v[3 * i] = m.v[i].x();
      v[3 * i + 1] = m.v[i].y();
      v[3 * i + 2] = m.v[i].z();
    }
    for (std::size_t i = 0; i < m.f.size(); ++i) {
      for (int k = 0; k < 3; ++k) f[3 * i + k] = m.f[i][k];
    }
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(scene);
    triangles += m.f.size();
    return scene;
  }

  static void SetTransform(RTCGeometry inst, const Pose& T) {
    float m[12];  // column-major 3x4
    for (int c = 0; c < 4; ++c) {
      for (int r = 0; r < 3; ++r) m[c * 3 + r] = float(T.matrix()(r, c));
    }
    rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, m);
  }

  unsigned Instance(RTCScene top, RTCScene child, const Pose& T, RTCGeometry* out = nullptr) {
    RTCGeometry inst = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(inst, child);
    SetTransform(inst, T);
    rtcCommitGeometry(inst);
    const unsigned id = rtcAttachGeometry(top, inst);
    if (out) *out = inst;
    rtcReleaseGeometry(inst);
    return id;
  }

  void Build() {
    permanent = MeshScene(sc.static_mesh, RTC_BUILD_QUALITY_HIGH);
    for (const auto& o : sc.ld) ld.push_back(MeshScene(o.mesh, RTC_BUILD_QUALITY_HIGH));
    car = MeshScene(sc.car_mesh, RTC_BUILD_QUALITY_HIGH);
    pedestrian = MeshScene(sc.pedestrian_mesh, RTC_BUILD_QUALITY_HIGH);
    triangles -= sc.car_mesh.f.size() + sc.pedestrian_mesh.f.size();
    sessions.resize(sc.sessions.size());
    for (std::size_t s = 0; s < sc.sessions.size(); ++s) {
      SessionScene& ss = sessions[s];
      ss.top = rtcNewScene(device);
      rtcSetSceneFlags(ss.top, RTC_SCENE_FLAG_DYNAMIC);
      rtcSetSceneBuildQuality(ss.top, RTC_BUILD_QUALITY_LOW);
      auto put = [&](unsigned id, InstanceKind k) {
        if (ss.inst.size() <= id) ss.inst.resize(id + 1);
        ss.inst[id] = k;
      };
      put(Instance(ss.top, permanent, Pose::Identity()), {InstanceKind::kPermanent, -1});
      for (std::size_t i = 0; i < sc.ld.size(); ++i) {
        if (IsPresent(int(i), int(s))) put(Instance(ss.top, ld[i], Pose::Identity()), {InstanceKind::kLd, int(i)});
      }
      const auto& actors = sc.sessions[s].actors;
      ss.actor_geom.resize(actors.size());
      ss.actor_on.assign(actors.size(), true);
      ss.actor_rot.assign(actors.size(), Eigen::Matrix3f::Identity());
      for (std::size_t a = 0; a < actors.size(); ++a) {
        put(Instance(ss.top, actors[a].pedestrian ? pedestrian : car, Pose::Identity(), &ss.actor_geom[a]),
            {InstanceKind::kActor, int(a)});
      }
    }
  }

  bool IsPresent(int object, int session) const {
    if (object < 0 || object >= int(sc.ld.size())) return false;
    const auto& p = sc.ld[std::size_t(object)].info.present_in;
    return std::find(p.begin(), p.end(), session) != p.end();
  }

  void CheckIndex(int session, int keyframe) const {
    if (session < 0 || session >= int(sc.sessions.size())) throw Error("sim: no session " + std::to_string(session));
    if (keyframe < 0 || keyframe >= int(sc.sessions[std::size_t(session)].T_world_sensor.size())) {
      throw Error("sim: session " + std::to_string(session) + " has no keyframe " + std::to_string(keyframe));
    }
  }

  // Puts the session's actors where they are at the keyframe's time; actors off their paths or
  // beyond the LiDAR's reach are disabled.
  void SetKeyframe(int session, int keyframe) {
    CheckIndex(session, keyframe);
    SessionScene& ss = sessions[std::size_t(session)];
    if (ss.keyframe == keyframe) return;
    const auto& plan = sc.sessions[std::size_t(session)];
    const double t = keyframe * plan.seconds_per_keyframe;
    const Eigen::Vector3d sensor = plan.T_world_sensor[std::size_t(keyframe)].translation();
    for (std::size_t a = 0; a < plan.actors.size(); ++a) {
      Pose T;
      bool on = plan.actors[a].PoseAt(t, sc.grid, sc.terrain, &T) &&
                (T.translation() - sensor).norm() < sc.cfg.max_range_m + 10.0;
      RTCGeometry g = ss.actor_geom[a];
      if (on) {
        SetTransform(g, T);
        ss.actor_rot[a] = T.linear().cast<float>();
        rtcCommitGeometry(g);
      }
      if (on != ss.actor_on[a]) {
        if (on) rtcEnableGeometry(g);
        else rtcDisableGeometry(g);
        ss.actor_on[a] = on;
      }
    }
    arena.execute([&] { rtcCommitScene(ss.top); });
    Check("committing session " + std::to_string(session));
    ss.keyframe = keyframe;
  }

  // Label and intensity of a hit.
  void Resolve(int session, unsigned inst, unsigned prim, const Eigen::Vector3f& ng, const Eigen::Vector3f& dir,
               PointClass* cls, int* object, float* intensity, float* cos_incidence = nullptr,
               Eigen::Vector3f* normal = nullptr) const {
    const SessionScene& ss = sessions[std::size_t(session)];
    const InstanceKind k = ss.inst[inst];
    const detail::Mesh* mesh = &sc.static_mesh;
    Eigen::Vector3f n = ng;
    *cls = PointClass::kStatic;
    *object = -1;
    if (k.type == InstanceKind::kLd) {
      mesh = &sc.ld[std::size_t(k.index)].mesh;
      *object = sc.ld[std::size_t(k.index)].info.id;
    } else if (k.type == InstanceKind::kActor) {
      const auto& actor = sc.sessions[std::size_t(session)].actors[std::size_t(k.index)];
      mesh = actor.pedestrian ? &sc.pedestrian_mesh : &sc.car_mesh;
      n = ss.actor_rot[std::size_t(k.index)] * ng;  // Ng is in the instance's object space
      *cls = PointClass::kHD;
      *object = actor.id;
    }
    const float nn = n.norm();
    const float cosine = nn > 0 ? std::abs(n.dot(dir)) / nn : 1.0f;
    *intensity = 100.0f * detail::Reflectivity(mesh->mat[prim]) * cosine;
    if (cos_incidence) *cos_incidence = cosine;
    if (normal) *normal = nn > 0 ? Eigen::Vector3f(n / nn) : Eigen::Vector3f::Zero();
  }
};

Simulator::Simulator(const SimConfig& cfg, int threads) {
  CheckConfig(cfg);
  impl_ = std::make_unique<Impl>(cfg, threads);
}
Simulator::~Simulator() = default;

const SimConfig& Simulator::config() const { return impl_->sc.cfg; }
int Simulator::sessions() const { return int(impl_->sc.sessions.size()); }
int Simulator::keyframes(int s) const {
  impl_->CheckIndex(s, 0);
  return int(impl_->sc.sessions[std::size_t(s)].T_world_sensor.size());
}
std::size_t Simulator::triangles() const { return impl_->triangles; }
std::size_t Simulator::hd_actors() const {
  std::size_t n = 0;
  for (const auto& s : impl_->sc.sessions) n += s.actors.size();
  return n;
}
const std::vector<LdObjectInfo>& Simulator::ld_objects() const { return impl_->ld_info; }
std::vector<HdActorInfo> Simulator::hd_actor_info() const {
  std::vector<HdActorInfo> out;
  for (std::size_t s = 0; s < impl_->sc.sessions.size(); ++s) {
    for (const auto& a : impl_->sc.sessions[s].actors) {
      out.push_back({a.id, int(s), a.pedestrian ? "pedestrian" : "car", a.speed});
    }
  }
  return out;
}
bool Simulator::IsPresent(int o, int s) const { return impl_->IsPresent(o, s); }
Pose Simulator::T_world_session(int s) const {
  impl_->CheckIndex(s, 0);
  return impl_->sc.sessions[std::size_t(s)].T_world_session;
}
const std::vector<Pose>& Simulator::T_world_sensor(int s) const {
  impl_->CheckIndex(s, 0);
  return impl_->sc.sessions[std::size_t(s)].T_world_sensor;
}
std::vector<Pose> Simulator::T_session_sensor_true(int s) const {
  const Pose inv = T_world_session(s).inverse();
  std::vector<Pose> out;
  for (const auto& T : T_world_sensor(s)) out.push_back(inv * T);
  return out;
}
const std::vector<Pose>& Simulator::T_session_sensor_drifted(int s) const {
  impl_->CheckIndex(s, 0);
  return impl_->sc.sessions[std::size_t(s)].T_session_sensor_drifted;
}

namespace {

// Seconds after the keyframe at which column c is fired (the `time` a raw sweep's point carries).
double ColumnTime(const SimConfig& cfg, int c) { return cfg.sweep_s * c / cfg.columns; }

// The sensor pose `dt` seconds after keyframe k, on the way to keyframe k + 1 (constant velocity
// between keyframes: linear in translation, slerp in rotation; past the last keyframe the last
// step's motion continues).
Pose PoseAfter(const std::vector<Pose>& poses, std::size_t k, double dt, double seconds_per_keyframe) {
  if (dt == 0.0 || poses.size() < 2) return poses[k];
  const bool last = k + 1 >= poses.size();
  const Pose& a = last ? poses[k - 1] : poses[k];
  const Pose& b = last ? poses[k] : poses[k + 1];
  const double f = dt / seconds_per_keyframe + (last ? 1.0 : 0.0);
  const Eigen::Quaterniond qa(a.linear()), qb(b.linear());
  Pose T = Pose::Identity();
  T.linear() = qa.slerp(f, qb).toRotationMatrix();
  T.translation() = a.translation() + f * (b.translation() - a.translation());
  return T;
}

}  // namespace

double Simulator::KeyframeTime(int session, int keyframe) const {
  impl_->CheckIndex(session, keyframe);
  return keyframe * impl_->sc.sessions[std::size_t(session)].seconds_per_keyframe;
}

PointCloud Simulator::TrueDeskewed(int session, int keyframe, const PointCloud& scan) const {
  if (scan.time.empty()) return scan;
  const SimConfig& cfg = impl_->sc.cfg;
  const std::vector<Pose> sweep = SweepPoses(session, keyframe);
  const Pose T_inv = impl_->sc.sessions[std::size_t(session)].T_world_sensor[std::size_t(keyframe)].inverse();
  PointCloud out = scan;
  for (std::size_t i = 0; i < out.size(); ++i) {
    const long c = std::lround(double(out.time[i]) / cfg.sweep_s * cfg.columns);
    const Eigen::Vector3f q = (T_inv * sweep[std::size_t(std::clamp(c, 0L, long(cfg.columns) - 1))]).cast<float>() *
                              out.points[i].xyz();
    out.points[i].x = q.x(), out.points[i].y = q.y(), out.points[i].z = q.z();
  }
  out.time.clear();
  return out;
}

std::vector<Pose> Simulator::SweepPoses(int session, int keyframe) const {
  const Impl& I = *impl_;
  I.CheckIndex(session, keyframe);
  const SimConfig& cfg = I.sc.cfg;
  const auto& plan = I.sc.sessions[std::size_t(session)];
  std::vector<Pose> out(std::size_t(cfg.columns), plan.T_world_sensor[std::size_t(keyframe)]);
  if (cfg.sweep == "instant") return out;
  for (int c = 0; c < cfg.columns; ++c)
    out[std::size_t(c)] = PoseAfter(plan.T_world_sensor, std::size_t(keyframe), ColumnTime(cfg, c),
                                    plan.seconds_per_keyframe);
  return out;
}

namespace {
// One scan's rays before noise: range (-1 = no return), intensity, class and LD object per ray,
// ray i = beam * columns + column.
struct ScanRays {
  explicit ScanRays(std::size_t n) : range(n, -1.f), intensity(n, 0.f), cls(n, PointClass::kUnknown), object(n, -1) {}
  std::vector<float> range, intensity;
  std::vector<PointClass> cls;
  std::vector<std::int32_t> object;
};

// Embree packet of the beams b0 .. b0 + 15 of column c (lanes past the last beam invalid), fired
// from `o` with the sensor rotation R.
void FillPacket(const std::vector<Eigen::Vector3f>& dirs, int B, int C, int b0, int c, const Eigen::Matrix3f& R,
                const Eigen::Vector3f& o, float tnear, float tfar, int* valid, RTCRayHit16* rh) {
  for (int l = 0; l < 16; ++l) {
    const int b = b0 + l;
    valid[l] = b < B ? -1 : 0;
    const Eigen::Vector3f d = b < B ? Eigen::Vector3f(R * dirs[std::size_t(b) * C + c]) : Eigen::Vector3f::UnitX();
    rh->ray.org_x[l] = o.x();
    rh->ray.org_y[l] = o.y();
    rh->ray.org_z[l] = o.z();
    rh->ray.dir_x[l] = d.x();
    rh->ray.dir_y[l] = d.y();
    rh->ray.dir_z[l] = d.z();
    rh->ray.tnear[l] = tnear;
    rh->ray.tfar[l] = tfar;
    rh->ray.time[l] = 0.f;
    rh->ray.mask[l] = 0xFFFFFFFFu;
    rh->ray.id[l] = unsigned(l);
    rh->ray.flags[l] = 0;
    rh->hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    rh->hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
  }
}

// The returns with range noise and dropout from a hash of (seed, session, keyframe, ray), so
// thread-independent; points in the sensor frame of the ray's firing (raw sweep) or moved into the
// keyframe frame T (deskewed).
PointCloud NoisyPoints(const SimConfig& cfg, int session, int keyframe, const ScanRays& rays,
                       const std::vector<Eigen::Vector3f>& dirs, const std::vector<Pose>& sweep, const Pose& T) {
  PointCloud cloud;
  cloud.reserve(rays.range.size());
  const auto seed = std::uint64_t(cfg.seed);
  for (std::size_t i = 0; i < rays.range.size(); ++i) {
    if (rays.range[i] < 0) continue;
    const std::uint64_t h = detail::Hash(seed, std::uint64_t(session) + 1000, std::uint64_t(keyframe), i);
    if (detail::ToUnit(h) < cfg.dropout) continue;
    const double u1 = 1.0 - detail::ToUnit(detail::Mix(h ^ 0x5bd1e995ull)), u2 = detail::ToUnit(detail::Mix(h + 17));
    const double g = std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
    const float rr = float(rays.range[i] + cfg.range_noise_m * g);
    if (rr < cfg.min_range_m || rr > cfg.max_range_m) continue;
    Eigen::Vector3f p = dirs[i] * rr;  // the sensor frame when the ray was fired
    if (cfg.sweep == "deskewed") p = (T.inverse() * sweep[i % std::size_t(cfg.columns)]).cast<float>() * p;
    if (cfg.sweep == "distorted") cloud.time.push_back(float(ColumnTime(cfg, int(i % std::size_t(cfg.columns)))));
    cloud.push_back(p.x(), p.y(), p.z(), rays.intensity[i]);
    cloud.cls.push_back(rays.cls[i]);
    cloud.object.push_back(rays.object[i]);
  }
  cloud.session.assign(cloud.size(), std::uint16_t(session));
  return cloud;
}
}  // namespace

PointCloud Simulator::CastScan(int session, int keyframe) {
  Impl& I = *impl_;
  I.SetKeyframe(session, keyframe);
  const SimConfig& cfg = I.sc.cfg;
  const Pose& T = I.sc.sessions[std::size_t(session)].T_world_sensor[std::size_t(keyframe)];
  // Per column: the pose it is fired from (all T unless the sweep takes time).
  const std::vector<Pose> sweep = SweepPoses(session, keyframe);
  const int B = cfg.beams, C = cfg.columns;
  // Ray directions: the fixed beam x column table, or this scan's rosette.
  const std::vector<Eigen::Vector3f> rosette =
      cfg.lidar_pattern == "rosette"
          ? RosetteDirections(cfg, std::uint64_t(session) * 1000003u + std::uint64_t(keyframe))
          : std::vector<Eigen::Vector3f>();
  const std::vector<Eigen::Vector3f>& dirs = rosette.empty() ? I.dirs : rosette;
  ScanRays rays(std::size_t(B) * C);
  RTCScene top = I.sessions[std::size_t(session)].top;
  const float tnear = float(cfg.min_range_m), tfar = float(cfg.max_range_m);
  ParallelForChunks(std::size_t(C), I.threads, 8, [&](std::size_t begin, std::size_t end) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    alignas(64) int valid[16];
    RTCRayHit16 rh;
    for (int c = int(begin); c < int(end); ++c) {
      const Eigen::Matrix3f R = sweep[std::size_t(c)].linear().cast<float>();
      const Eigen::Vector3f o = sweep[std::size_t(c)].translation().cast<float>();
      for (int b0 = 0; b0 < B; b0 += 16) {
        FillPacket(dirs, B, C, b0, c, R, o, tnear, tfar, valid, &rh);
        rtcIntersect16(valid, top, &ctx, &rh);
        for (int l = 0; l < 16 && b0 + l < B; ++l) {
          if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) continue;
          const std::size_t i = std::size_t(b0 + l) * C + c;
          rays.range[i] = rh.ray.tfar[l];
          const Eigen::Vector3f d(rh.ray.dir_x[l], rh.ray.dir_y[l], rh.ray.dir_z[l]);
          I.Resolve(session, rh.hit.instID[0][l], rh.hit.primID[l], {rh.hit.Ng_x[l], rh.hit.Ng_y[l], rh.hit.Ng_z[l]},
                    d, &rays.cls[i], &rays.object[i], &rays.intensity[i]);
        }
      }
    }
  });
  I.Check("casting a scan");
  return NoisyPoints(cfg, session, keyframe, rays, dirs, sweep, T);
}

std::vector<RayHit> Simulator::CastRays(int session, int keyframe, const Eigen::Vector3d& origin,
                                        const std::vector<Eigen::Vector3f>& dirs) {
  return CastRays(session, keyframe, std::vector<Eigen::Vector3f>(dirs.size(), origin.cast<float>()), dirs);
}

std::vector<RayHit> Simulator::CastRays(int session, int keyframe, const std::vector<Eigen::Vector3f>& origins,
                                        const std::vector<Eigen::Vector3f>& dirs) {
  if (origins.size() != dirs.size()) throw Error("sim: CastRays needs one origin per ray");
  Impl& I = *impl_;
  I.SetKeyframe(session, keyframe);
  std::vector<RayHit> out(dirs.size());
  RTCScene top = I.sessions[std::size_t(session)].top;
  const float tfar = float(I.sc.cfg.max_range_m);
  ParallelForChunks(dirs.size(), I.threads, 64, [&](std::size_t begin, std::size_t end) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (std::size_t i = begin; i < end; ++i) {
      RTCRayHit rh;
      rh.ray.org_x = origins[i].x();
      rh.ray.org_y = origins[i].y();
      rh.ray.org_z = origins[i].z();
      rh.ray.dir_x = dirs[i].x();
      rh.ray.dir_y = dirs[i].y();
      rh.ray.dir_z = dirs[i].z();
      rh.ray.tnear = 0.f;
      rh.ray.tfar = tfar;
      rh.ray.time = 0.f;
      rh.ray.mask = 0xFFFFFFFFu;
      rh.ray.id = 0;
      rh.ray.flags = 0;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(top, &ctx, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
      RayHit& h = out[i];
      h.hit = true;
      h.range = rh.ray.tfar;
      float intensity;
      I.Resolve(session, rh.hit.instID[0], rh.hit.primID, {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z}, dirs[i],
                &h.cls, &h.object, &intensity, &h.cos_incidence, &h.normal);
    }
  });
  I.Check("casting rays");
  return out;
}

void Simulator::FiredRays(int session, int keyframe, std::vector<Eigen::Vector3f>* origins,
                          std::vector<Eigen::Vector3f>* dirs_world) const {
  const Impl& I = *impl_;
  const SimConfig& cfg = I.sc.cfg;
  const std::vector<Pose> sweep = SweepPoses(session, keyframe);
  const std::vector<Eigen::Vector3f> rosette =
      cfg.lidar_pattern == "rosette"
          ? RosetteDirections(cfg, std::uint64_t(session) * 1000003u + std::uint64_t(keyframe))
          : std::vector<Eigen::Vector3f>();
  const std::vector<Eigen::Vector3f>& dirs = rosette.empty() ? I.dirs : rosette;
  const int B = cfg.beams, C = cfg.columns;
  origins->resize(std::size_t(B) * C);
  dirs_world->resize(std::size_t(B) * C);
  for (int c = 0; c < C; ++c) {
    const Eigen::Matrix3f R = sweep[std::size_t(c)].linear().cast<float>();
    const Eigen::Vector3f o = sweep[std::size_t(c)].translation().cast<float>();
    for (int b = 0; b < B; ++b) {
      const std::size_t i = std::size_t(b) * C + c;
      (*origins)[i] = o;
      (*dirs_world)[i] = R * dirs[i];  // as FillPacket fires it
    }
  }
}

}  // namespace ltm::sim
