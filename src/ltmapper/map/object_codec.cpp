// Byte layout of one step's objects in the store's cache (objects.cpp), little endian:
//   u32 version, u32 kept count, u32 rejected count, then each object: i32 session, reference,
//   exists_in; u8 class; string change, rejected (u32 length + bytes); u64 points; f64 confidence,
//   centroid, lo, hi, box_center, size (3 each), yaw, ground_z, height_above_ground, clearance,
//   range, observed, twin, attached, box seen (version 2; version 1 has none: 0) fractions; u32
//   alike beside (version 3; before: 0); f64 hidden length (version 4; before: 0); u32 cloud points, then the arrays f32 x, y, z, intensity,
//   u8 class, u16 session, each as byte planes (all lowest bytes first). Ids and partners are not
//   stored: Store::Objects assigns them over all steps. The reader checks every length against the
//   bytes left.
#include "ltmapper/map/detail.hpp"

#include <cstring>

namespace ltm::map::detail {
namespace {

constexpr std::uint32_t kObjectsVersion = 4;
constexpr std::uint32_t kOldestObjectsVersion = 1;  // without box_seen_fraction
constexpr std::uint32_t kBoxSeenSince = 2;          // the first version holding box_seen_fraction
constexpr std::uint32_t kAlikeSince = 3;            // the first version holding alike_beside
constexpr std::uint32_t kHiddenSince = 4;           // the first version holding hidden_length_m

class Writer {
 public:
  template <class T>
  void Put(T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    out_.append(b, sizeof(T));
  }
  void Put(const std::string& s) {
    Put(std::uint32_t(s.size()));
    out_ += s;
  }
  void Put(const Eigen::Vector3d& v) {
    for (int k = 0; k < 3; ++k) Put(v[k]);
  }
  // n values of one type as byte planes (all lowest bytes first): neighbouring points' high bytes
  // agree, so zstd packs the planes far better than the interleaved values.
  template <class Get>
  void PutPlanes(std::size_t n, Get get) {
    using T = decltype(get(0));
    const std::size_t base = out_.size();
    out_.resize(base + n * sizeof(T));
    for (std::size_t i = 0; i < n; ++i) {
      const T v = get(i);
      char b[sizeof(T)];
      std::memcpy(b, &v, sizeof(T));
      for (std::size_t k = 0; k < sizeof(T); ++k) out_[base + k * n + i] = b[k];
    }
  }
  std::string Take() { return std::move(out_); }

 private:
  std::string out_;
};

class Reader {
 public:
  Reader(const std::string& in, const std::string& what) : in_(in), what_(what) {}
  template <class T>
  T Get() {
    Need(sizeof(T));
    T v;
    std::memcpy(&v, in_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::string GetString() {
    const std::size_t n = Get<std::uint32_t>();
    Need(n);
    std::string s = in_.substr(pos_, n);
    pos_ += n;
    return s;
  }
  Eigen::Vector3d GetVector() {
    Eigen::Vector3d v;
    for (int k = 0; k < 3; ++k) v[k] = Get<double>();
    return v;
  }
  // A count of items of at least `bytes_each` bytes: no more than the bytes left can hold.
  std::size_t GetCount(std::size_t bytes_each) {
    const std::size_t n = Get<std::uint32_t>();
    Need(n * bytes_each);
    return n;
  }
  template <class T, class Set>
  void GetPlanes(std::size_t n, Set set) {
    Need(n * sizeof(T));
    for (std::size_t i = 0; i < n; ++i) {
      char b[sizeof(T)];
      for (std::size_t k = 0; k < sizeof(T); ++k) b[k] = in_[pos_ + k * n + i];
      T v;
      std::memcpy(&v, b, sizeof(T));
      set(i, v);
    }
    pos_ += n * sizeof(T);
  }
  bool AtEnd() const { return pos_ == in_.size(); }
  void Need(std::size_t n) const {
    if (n > in_.size() - pos_) throw Error(what_ + ": object record truncated");
  }

 private:
  const std::string& in_;
  std::string what_;
  std::size_t pos_ = 0;
};

constexpr std::size_t kPointBytes = 4 * sizeof(float) + 1 + sizeof(std::uint16_t);

void PutObject(Writer& w, const MapObject& o) {
  w.Put(std::int32_t(o.session)), w.Put(std::int32_t(o.reference)), w.Put(std::int32_t(o.exists_in));
  w.Put(std::uint8_t(o.cls));
  w.Put(o.change), w.Put(o.rejected);
  w.Put(std::uint64_t(o.points));
  w.Put(o.confidence);
  for (const auto* v : {&o.centroid, &o.lo, &o.hi, &o.box_center, &o.size}) w.Put(*v);
  for (double d : {o.yaw_rad, o.ground_z, o.height_above_ground, o.clearance_m, o.range_m, o.observed_fraction,
                   o.twin_fraction, o.attached_fraction, o.box_seen_fraction})
    w.Put(d);
  w.Put(std::uint32_t(o.alike_beside));
  w.Put(o.hidden_length_m);
  const PointCloud& c = o.cloud;
  w.Put(std::uint32_t(c.size()));
  for (const auto field : {&PointXYZI::x, &PointXYZI::y, &PointXYZI::z, &PointXYZI::intensity})
    w.PutPlanes(c.size(), [&](std::size_t i) { return c.points[i].*field; });
  w.PutPlanes(c.size(), [&](std::size_t i) { return std::uint8_t(c.cls.empty() ? PointClass::kUnknown : c.cls[i]); });
  w.PutPlanes(c.size(), [&](std::size_t i) { return c.session.empty() ? std::uint16_t(0) : c.session[i]; });
}

MapObject GetObject(Reader& r, std::uint32_t version) {
  MapObject o;
  o.session = r.Get<std::int32_t>(), o.reference = r.Get<std::int32_t>(), o.exists_in = r.Get<std::int32_t>();
  o.cls = PointClass(r.Get<std::uint8_t>());
  o.change = r.GetString(), o.rejected = r.GetString();
  o.points = std::size_t(r.Get<std::uint64_t>());
  o.confidence = r.Get<double>();
  for (auto* v : {&o.centroid, &o.lo, &o.hi, &o.box_center, &o.size}) *v = r.GetVector();
  for (double* d : {&o.yaw_rad, &o.ground_z, &o.height_above_ground, &o.clearance_m, &o.range_m,
                    &o.observed_fraction, &o.twin_fraction, &o.attached_fraction})
    *d = r.Get<double>();
  if (version >= kBoxSeenSince) o.box_seen_fraction = r.Get<double>();
  if (version >= kAlikeSince) o.alike_beside = r.Get<std::uint32_t>();
  if (version >= kHiddenSince) o.hidden_length_m = r.Get<double>();
  const std::size_t n = r.GetCount(kPointBytes);
  PointCloud& c = o.cloud;
  c.points.resize(n), c.cls.resize(n), c.session.resize(n);
  for (const auto field : {&PointXYZI::x, &PointXYZI::y, &PointXYZI::z, &PointXYZI::intensity})
    r.GetPlanes<float>(n, [&](std::size_t i, float v) { c.points[i].*field = v; });
  r.GetPlanes<std::uint8_t>(n, [&](std::size_t i, std::uint8_t v) { c.cls[i] = PointClass(v); });
  r.GetPlanes<std::uint16_t>(n, [&](std::size_t i, std::uint16_t v) { c.session[i] = v; });
  if (n == 0) c.cls.clear(), c.session.clear();
  return o;
}

}  // namespace

std::string EncodeObjects(const std::vector<MapObject>& kept, const std::vector<MapObject>& rejected) {
  Writer w;
  w.Put(kObjectsVersion);
  w.Put(std::uint32_t(kept.size())), w.Put(std::uint32_t(rejected.size()));
  for (const auto* list : {&kept, &rejected})
    for (const auto& o : *list) PutObject(w, o);
  return w.Take();
}

void DecodeObjects(const std::string& raw, const std::string& what, std::vector<MapObject>* kept,
                   std::vector<MapObject>* rejected) {
  Reader r(raw, what);
  const auto version = r.Get<std::uint32_t>();
  if (version < kOldestObjectsVersion || version > kObjectsVersion)
    throw Error(what + ": object record version " + std::to_string(version) + ", expected " +
                std::to_string(kOldestObjectsVersion) + " to " + std::to_string(kObjectsVersion));
  const std::size_t nk = r.Get<std::uint32_t>(), nr = r.Get<std::uint32_t>();
  kept->clear(), rejected->clear();
  for (std::size_t k = 0; k < nk + nr; ++k) (k < nk ? kept : rejected)->push_back(GetObject(r, version));
  if (!r.AtEnd()) throw Error(what + ": object record has trailing bytes");
}

}  // namespace ltm::map::detail
