// Blob codec: quantised coordinates relative to a per-blob origin, byte-plane shuffled, zstd,
// FNV-1a 64 checksum over header and payload (layout in README.md).
#include "ltmapper/map/detail.hpp"

#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "the blob codec writes little-endian fields with memcpy; port it for big-endian hosts"
#endif

namespace ltm::map::detail {
namespace {

constexpr char kMagic[4] = {'L', 'T', 'M', 'B'};
// Blob versions: 1 (stores of schema version 1) seeded the checksum with a truncated FNV offset
// basis, 2 with FNV-1a 64's own; the layout is the same. New blobs are version 2, both decode.
constexpr std::uint16_t kVersionLegacyBasis = 1;
constexpr std::uint16_t kVersion = 2;
constexpr std::uint64_t kLegacyFnvBasis = 1469598103934665603ull;  // 14695981039346656037 missing its last digit
constexpr std::size_t kHeaderSize = 64;
constexpr std::size_t kChecksumOffset = 56;
// Most bytes zstd can produce per compressed byte: a block holds at most 128 KiB
// (ZSTD_BLOCKSIZE_MAX) and costs at least 4 bytes (3-byte block header + 1 RLE byte), so a
// stated raw size above compressed size x 32768 is a lie, refused before allocating it.
constexpr std::size_t kZstdMaxRatio = (std::size_t(1) << 17) / 4;

std::uint64_t ChecksumBasis(std::uint16_t version) {
  return version == kVersionLegacyBasis ? kLegacyFnvBasis : kFnvOffsetBasis;
}

template <class T>
void Put(std::string& s, std::size_t off, T v) {
  std::memcpy(&s[off], &v, sizeof(T));
}
template <class T>
T Get(const unsigned char* p, std::size_t off) {
  T v;
  std::memcpy(&v, p + off, sizeof(T));
  return v;
}

// `header` zero bytes (for the caller's header) followed by the zstd frame of `raw`.
std::string CompressAfter(std::size_t header, const std::string& raw, int zstd_level, const char* what) {
  std::string out(header + ZSTD_compressBound(raw.size()), '\0');
  const std::size_t comp = ZSTD_compress(&out[header], out.size() - header, raw.data(), raw.size(), zstd_level);
  if (ZSTD_isError(comp)) throw Error(std::string(what) + ": zstd compression failed: " + ZSTD_getErrorName(comp));
  out.resize(header + comp);
  return out;
}

int WidthFor(std::uint64_t span) { return span <= 0xFF ? 1 : span <= 0xFFFF ? 2 : 4; }

// Writes n values (offsets from `origin`) as `w` byte planes: all low bytes, then the next ...
template <class Getter>
void PutPlanes(std::string& out, std::size_t n, int w, std::int32_t origin, Getter get) {
  const std::size_t base = out.size();
  out.resize(base + n * std::size_t(w));
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint32_t v = std::uint32_t(std::int64_t(get(k)) - origin);
    for (int b = 0; b < w; ++b) out[base + std::size_t(b) * n + k] = char((v >> (8 * b)) & 0xFF);
  }
}
template <class Setter>
void GetPlanes(const unsigned char* p, std::size_t n, int w, std::int32_t origin, Setter set) {
  for (std::size_t k = 0; k < n; ++k) {
    std::uint32_t v = 0;
    for (int b = 0; b < w; ++b) v |= std::uint32_t(p[std::size_t(b) * n + k]) << (8 * b);
    set(k, std::int32_t(std::int64_t(origin) + std::int64_t(v)));
  }
}

// The `raw_size` bytes a zstd payload of `comp` bytes decompresses to. The stated size is checked
// against what the payload can hold before it is allocated (a 74-byte blob once claimed 2.4 GB):
// zstd's ratio bound and the frame's own content size; `fail(why)` throws.
template <class Fail>
std::string Decompress(const unsigned char* payload, std::size_t comp, std::size_t raw_size, const Fail& fail) {
  if (raw_size > comp * kZstdMaxRatio)
    fail("raw size " + std::to_string(raw_size) + " cannot come from " + std::to_string(comp) + " compressed bytes");
  const unsigned long long frame_size = ZSTD_getFrameContentSize(payload, comp);
  if (frame_size != raw_size)
    fail("raw size " + std::to_string(raw_size) + " but the zstd frame holds " +
         (ZSTD_isError(frame_size) || frame_size == ZSTD_CONTENTSIZE_UNKNOWN ? std::string("an unknown size")
                                                                             : std::to_string(frame_size) + " bytes"));
  std::string raw(raw_size, '\0');
  const std::size_t got = ZSTD_decompress(raw.data(), raw.size(), payload, comp);
  if (ZSTD_isError(got)) fail(std::string("zstd: ") + ZSTD_getErrorName(got));
  if (got != raw_size) fail("decompressed size mismatch");
  return raw;
}

}  // namespace

std::uint64_t Fnv1a64(const void* data, std::size_t size, std::uint64_t h) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t k = 0; k < size; ++k) {
    h ^= p[k];
    h *= 1099511628211ull;
  }
  return h;
}

// ------------------------------------------------------------------------------ quantisation
QCloud Quantize(const PointCloud& cloud, double resolution_m, double intensity_step,
                PointClass default_cls, std::uint16_t default_session, const std::string& what) {
  cloud.CheckConsistent(what);
  QCloud q(cloud.size());
  const double inv = 1.0 / resolution_m, iinv = 1.0 / intensity_step;
  for (std::size_t k = 0; k < cloud.size(); ++k) {
    const PointXYZI& p = cloud.points[k];
    const double v[3] = {std::nearbyint(p.x * inv), std::nearbyint(p.y * inv), std::nearbyint(p.z * inv)};
    const double vi = std::nearbyint(p.intensity * iinv);
    for (double c : v) {
      if (!std::isfinite(c) || std::fabs(c) > kMaxCoord) {
        std::ostringstream os;
        os << what << ": point " << k << " (" << p.x << ", " << p.y << ", " << p.z
           << ") is non-finite or farther than " << kMaxCoord * resolution_m
           << " m from the keyframe origin (resolution_m " << resolution_m << ")";
        throw Error(os.str());
      }
    }
    if (!std::isfinite(vi) || std::fabs(vi) > double(std::numeric_limits<std::int32_t>::max() / 2)) {
      std::ostringstream os;
      os << what << ": point " << k << " intensity " << p.intensity << " is not representable with step "
         << intensity_step;
      throw Error(os.str());
    }
    QPoint& o = q[k];
    o.x = std::int32_t(v[0]);
    o.y = std::int32_t(v[1]);
    o.z = std::int32_t(v[2]);
    o.i = std::int32_t(vi);
    o.cls = std::uint8_t(cloud.cls.empty() ? default_cls : cloud.cls[k]);
    o.session = cloud.session.empty() ? default_session : cloud.session[k];
    o.role = kAdded;
  }
  return q;
}

PointCloud Dequantize(const QCloud& q, double resolution_m, double intensity_step) {
  PointCloud c;
  c.points.resize(q.size());
  c.cls.resize(q.size());
  c.session.resize(q.size());
  for (std::size_t k = 0; k < q.size(); ++k) {
    const QPoint& p = q[k];
    c.points[k] = {float(p.x * resolution_m), float(p.y * resolution_m), float(p.z * resolution_m),
                   float(p.i * intensity_step)};
    c.cls[k] = PointClass(p.cls);
    c.session[k] = p.session;
  }
  return c;
}

// -------------------------------------------------------------------------------- codec
std::string EncodeQ(const QCloud& q, double resolution_m, double intensity_step, int zstd_level) {
  const std::size_t n = q.size();
  if (n > std::numeric_limits<std::uint32_t>::max() / 32) throw Error("blob: too many points");
  std::int32_t lo[4] = {0, 0, 0, 0}, hi[4] = {0, 0, 0, 0};
  if (n) {
    lo[0] = hi[0] = q[0].x, lo[1] = hi[1] = q[0].y, lo[2] = hi[2] = q[0].z, lo[3] = hi[3] = q[0].i;
  }
  for (const QPoint& p : q) {
    const std::int32_t v[4] = {p.x, p.y, p.z, p.i};
    for (int a = 0; a < 4; ++a) lo[a] = std::min(lo[a], v[a]), hi[a] = std::max(hi[a], v[a]);
  }
  std::uint64_t span_xyz = 0;
  for (int a = 0; a < 3; ++a) span_xyz = std::max<std::uint64_t>(span_xyz, std::uint64_t(std::int64_t(hi[a]) - lo[a]));
  const int wxyz = WidthFor(span_xyz), wi = WidthFor(std::uint64_t(std::int64_t(hi[3]) - lo[3]));

  std::string raw;
  raw.reserve(n * std::size_t(3 * wxyz + wi + 4));
  PutPlanes(raw, n, wxyz, lo[0], [&](std::size_t k) { return q[k].x; });
  PutPlanes(raw, n, wxyz, lo[1], [&](std::size_t k) { return q[k].y; });
  PutPlanes(raw, n, wxyz, lo[2], [&](std::size_t k) { return q[k].z; });
  PutPlanes(raw, n, wi, lo[3], [&](std::size_t k) { return q[k].i; });
  PutPlanes(raw, n, 1, 0, [&](std::size_t k) { return std::int32_t(q[k].cls); });
  PutPlanes(raw, n, 1, 0, [&](std::size_t k) { return std::int32_t(q[k].role); });
  PutPlanes(raw, n, 2, 0, [&](std::size_t k) { return std::int32_t(q[k].session); });

  std::string out = CompressAfter(kHeaderSize, raw, zstd_level, "blob");
  const std::size_t comp = out.size() - kHeaderSize;
  std::memcpy(&out[0], kMagic, 4);
  Put<std::uint16_t>(out, 4, kVersion);
  Put<std::uint8_t>(out, 6, std::uint8_t(wxyz));
  Put<std::uint8_t>(out, 7, std::uint8_t(wi));
  Put<std::uint32_t>(out, 8, std::uint32_t(n));
  Put<std::uint32_t>(out, 12, std::uint32_t(raw.size()));
  Put<std::uint32_t>(out, 16, std::uint32_t(comp));
  Put<std::uint32_t>(out, 20, 0);
  Put<double>(out, 24, resolution_m);
  Put<double>(out, 32, intensity_step);
  for (int a = 0; a < 4; ++a) Put<std::int32_t>(out, 40 + 4 * std::size_t(a), lo[a]);
  std::uint64_t h = Fnv1a64(out.data(), kChecksumOffset, ChecksumBasis(kVersion));
  h = Fnv1a64(out.data() + kHeaderSize, comp, h);
  Put<std::uint64_t>(out, kChecksumOffset, h);
  return out;
}

QCloud DecodeQ(const void* data, std::size_t size, const std::string& what, double* resolution_m,
               double* intensity_step) {
  const auto* p = static_cast<const unsigned char*>(data);
  auto fail = [&](const std::string& why) -> void { throw Error(what + ": corrupt blob: " + why); };
  if (size < kHeaderSize) fail("shorter than its header (" + std::to_string(size) + " bytes)");
  if (std::memcmp(p, kMagic, 4) != 0) fail("bad magic");
  const std::uint16_t version = Get<std::uint16_t>(p, 4);
  if (version != kVersion && version != kVersionLegacyBasis)
    fail("unsupported blob version " + std::to_string(version));
  const int wxyz = Get<std::uint8_t>(p, 6), wi = Get<std::uint8_t>(p, 7);
  const std::size_t n = Get<std::uint32_t>(p, 8), raw_size = Get<std::uint32_t>(p, 12),
                    comp = Get<std::uint32_t>(p, 16);
  if (kHeaderSize + comp != size) fail("payload size " + std::to_string(comp) + " != blob size - header");
  std::uint64_t h = Fnv1a64(p, kChecksumOffset, ChecksumBasis(version));
  h = Fnv1a64(p + kHeaderSize, comp, h);
  if (h != Get<std::uint64_t>(p, kChecksumOffset)) fail("checksum mismatch");
  auto valid_w = [](int w) { return w == 1 || w == 2 || w == 4; };
  if (!valid_w(wxyz) || !valid_w(wi)) fail("bad field widths");
  if (raw_size != n * std::size_t(3 * wxyz + wi + 4)) fail("raw size does not match the point count");
  const double res = Get<double>(p, 24), istep = Get<double>(p, 32);
  if (!(res > 0) || !(istep > 0)) fail("bad resolution");
  std::int32_t lo[4];
  for (int a = 0; a < 4; ++a) lo[a] = Get<std::int32_t>(p, 40 + 4 * std::size_t(a));
  const std::string raw = Decompress(p + kHeaderSize, comp, raw_size, fail);

  QCloud q(n);
  const auto* r = reinterpret_cast<const unsigned char*>(raw.data());
  GetPlanes(r, n, wxyz, lo[0], [&](std::size_t k, std::int32_t v) { q[k].x = v; });
  r += n * std::size_t(wxyz);
  GetPlanes(r, n, wxyz, lo[1], [&](std::size_t k, std::int32_t v) { q[k].y = v; });
  r += n * std::size_t(wxyz);
  GetPlanes(r, n, wxyz, lo[2], [&](std::size_t k, std::int32_t v) { q[k].z = v; });
  r += n * std::size_t(wxyz);
  GetPlanes(r, n, wi, lo[3], [&](std::size_t k, std::int32_t v) { q[k].i = v; });
  r += n * std::size_t(wi);
  for (std::size_t k = 0; k < n; ++k) q[k].cls = r[k];
  r += n;
  for (std::size_t k = 0; k < n; ++k) q[k].role = r[k];
  r += n;
  for (std::size_t k = 0; k < n; ++k) q[k].session = std::uint16_t(r[k] | (r[n + k] << 8));
  if (resolution_m) *resolution_m = res;
  if (intensity_step) *intensity_step = istep;
  return q;
}

namespace {
constexpr char kPackMagic[4] = {'L', 'T', 'M', 'C'};
constexpr std::size_t kPackHeader = 4 + 8 + 8;  // magic, raw size, FNV-1a 64 of the payload
}  // namespace

std::string PackBytes(const std::string& raw, int zstd_level) {
  std::string out = CompressAfter(kPackHeader, raw, zstd_level, "pack");
  std::memcpy(&out[0], kPackMagic, sizeof(kPackMagic));
  Put<std::uint64_t>(out, 4, raw.size());
  Put<std::uint64_t>(out, 12, Fnv1a64(out.data() + kPackHeader, out.size() - kPackHeader));
  return out;
}

std::string UnpackBytes(const void* data, std::size_t size, const std::string& what) {
  const auto fail = [&](const std::string& why) { throw Error(what + ": " + why); };
  const auto* p = static_cast<const unsigned char*>(data);
  if (size < kPackHeader || std::memcmp(p, kPackMagic, sizeof(kPackMagic)) != 0) fail("not a packed record");
  if (Get<std::uint64_t>(p, 12) != Fnv1a64(p + kPackHeader, size - kPackHeader)) fail("checksum mismatch");
  return Decompress(p + kPackHeader, size - kPackHeader, std::size_t(Get<std::uint64_t>(p, 4)), fail);
}

}  // namespace ltm::map::detail

namespace ltm::map {

std::string EncodeBlob(const PointCloud& cloud, double resolution_m, double intensity_step, int zstd_level) {
  const auto q = detail::Quantize(cloud, resolution_m, intensity_step, PointClass::kUnknown, 0, "EncodeBlob");
  return detail::EncodeQ(q, resolution_m, intensity_step, zstd_level);
}

PointCloud DecodeBlob(const std::string& blob, const std::string& what) {
  double res = 0, istep = 0;
  const auto q = detail::DecodeQ(blob.data(), blob.size(), what, &res, &istep);
  return detail::Dequantize(q, res, istep);
}

}  // namespace ltm::map
