// Outputs: labelled PCD / PLY clouds, object tables, the `log` text.
#include "ltmapper/map/files.hpp"

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iterator>
#include <map>
#include <ostream>
#include <set>
#include <sstream>

namespace ltm::map {
namespace {

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Binary PCD with x y z intensity (float), class (uchar), session (ushort), object (int).
constexpr std::size_t kRecordBytes = 23;
// WIDTH and POINTS of a streamed PCD are written as this many digits (zero-padded; any PCD reader
// parses them) and filled in once the count is known, in place.
constexpr int kCountDigits = 20;

std::string PcdHeader(std::size_t n, bool padded) {
  std::ostringstream count;
  if (padded) count << std::setw(kCountDigits) << std::setfill('0');
  count << n;
  return "# .PCD v0.7 - Point Cloud Data file format (ltmapper map)\nVERSION 0.7\n"
         "FIELDS x y z intensity class session object\nSIZE 4 4 4 4 1 2 4\nTYPE F F F F U U I\n"
         "COUNT 1 1 1 1 1 1 1\nWIDTH " + count.str() + "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
         count.str() + "\nDATA binary\n";
}

// Point i of a cloud as one record (the PCD's body, and the tile spill's format).
void PackRecord(char* p, const PointCloud& cloud, std::size_t i) {
  std::memcpy(p, &cloud.points[i], 16);
  const std::uint8_t c = cloud.cls.empty() ? 0 : std::uint8_t(cloud.cls[i]);
  const std::uint16_t s = cloud.session.empty() ? 0 : cloud.session[i];
  const std::int32_t o = cloud.object.empty() ? -1 : cloud.object[i];
  std::memcpy(p + 16, &c, 1);
  std::memcpy(p + 17, &s, 2);
  std::memcpy(p + 19, &o, 4);
}

// The cloud's records, in batches.
void WriteRecords(std::ostream& os, const PointCloud& cloud) {
  const std::size_t n = cloud.size();
  std::string buf;
  constexpr std::size_t kBatch = 1 << 16;
  for (std::size_t b = 0; b < n; b += kBatch) {
    const std::size_t m = std::min(kBatch, n - b);
    buf.assign(m * kRecordBytes, '\0');
    for (std::size_t k = 0; k < m; ++k) PackRecord(&buf[k * kRecordBytes], cloud, b + k);
    os.write(buf.data(), std::streamsize(buf.size()));
  }
}

// Records back into a cloud (cls and session set; object only when some record has one).
PointCloud ReadRecords(const std::string& bytes) {
  const std::size_t n = bytes.size() / kRecordBytes;
  PointCloud c;
  c.points.resize(n);
  c.cls.resize(n);
  c.session.resize(n);
  std::vector<std::int32_t> object(n);
  bool any_object = false;
  for (std::size_t i = 0; i < n; ++i) {
    const char* p = bytes.data() + i * kRecordBytes;
    std::uint8_t cls = 0;
    std::memcpy(&c.points[i], p, 16);
    std::memcpy(&cls, p + 16, 1);
    std::memcpy(&c.session[i], p + 17, 2);
    std::memcpy(&object[i], p + 19, 4);
    c.cls[i] = PointClass(cls);
    any_object = any_object || object[i] != -1;
  }
  if (any_object) c.object = std::move(object);
  return c;
}

void WriteLabelledPcd(const std::string& path, const PointCloud& cloud) {
  io::WriteFileAtomic(path, [&](std::ostream& os) {
    os << PcdHeader(cloud.size(), false);
    WriteRecords(os, cloud);
  });
}

// Streamed parts in world tiles on disk (a temporary folder next to the output): a tile is a
// square of whole voxels, so voxelising tile by tile gives the voxels of the whole map, while
// memory holds one tile. Tile files are appended to from buffers of at most kSpillBufferBytes.
class TileSpill {
 public:
  TileSpill(const std::string& dir, double voxel_m)
      : dir_(dir), voxel_m_(voxel_m), voxels_per_tile_(std::max<std::int64_t>(1, std::int64_t(std::ceil(kSpillTileM / voxel_m)))) {
    std::filesystem::remove_all(dir_);
    io::MakeDirs(dir_);
  }
  ~TileSpill() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  void Add(const PointCloud& part) {
    for (std::size_t i = 0; i < part.size(); ++i) {
      std::string& b = buffers_[TileOf(part.points[i])];
      b.resize(b.size() + kRecordBytes);
      PackRecord(&b[b.size() - kRecordBytes], part, i);
    }
    buffered_ += part.size() * kRecordBytes;
    if (buffered_ > kSpillBufferBytes) Flush();
  }
  // Each tile's cloud (tiles in key order, points in the order they came).
  void ForEachTile(const std::function<void(PointCloud&&)>& f) {
    Flush();
    for (const std::int64_t key : tiles_) {
      std::ifstream in(File(key), std::ios::binary);
      const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      if (!in.eof() && in.fail()) throw Error(File(key) + ": cannot read the spilled tile back");
      f(ReadRecords(bytes));
    }
  }

 private:
  static constexpr double kSpillTileM = 32.0;                // tile edge (rounded up to whole voxels)
  static constexpr std::size_t kSpillBufferBytes = 16 << 20;  // records buffered before appending to files
  std::int64_t TileOf(const PointXYZI& p) const {
    auto tile = [&](float v) {
      const auto voxel = std::int64_t(std::floor(double(v) / voxel_m_));
      return voxel >= 0 ? voxel / voxels_per_tile_ : -((-voxel + voxels_per_tile_ - 1) / voxels_per_tile_);
    };
    return std::int64_t((std::uint64_t(tile(p.x)) << 32) ^ std::uint64_t(std::uint32_t(tile(p.y))));
  }
  std::string File(std::int64_t key) const { return dir_ + "/" + std::to_string(key) + ".bin"; }
  void Flush() {
    for (auto& [key, b] : buffers_) {
      std::ofstream out(File(key), std::ios::binary | std::ios::app);
      out.write(b.data(), std::streamsize(b.size()));
      if (!out) throw Error(File(key) + ": cannot spill a map tile (disk full?)");
      tiles_.insert(key);
    }
    buffers_.clear();
    buffered_ = 0;
  }
  std::string dir_;
  double voxel_m_;
  std::int64_t voxels_per_tile_;
  std::map<std::int64_t, std::string> buffers_;
  std::set<std::int64_t> tiles_;
  std::size_t buffered_ = 0;
};

std::string Bytes(std::size_t b) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.2f MB", double(b) / 1e6);
  return buf;
}

}  // namespace

std::size_t WriteLabelledCloudParts(const std::string& path, double voxel_m,
                                    const std::function<void(const PartSink&)>& parts, int threads) {
  if (!EndsWith(path, ".pcd")) {  // PLY: the whole cloud, then the PLY writer
    std::vector<PointCloud> all;
    parts([&](PointCloud&& p) { all.push_back(std::move(p)); });
    PointCloud c;
    for (auto& p : all) c.append(p), p = PointCloud();
    if (voxel_m > 0 && !c.empty()) c = geometry::VoxelDownsample(c, voxel_m, threads);
    WriteLabelledCloud(path, c);
    return c.size();
  }
  std::size_t n = 0;
  io::WriteFileAtomic(path, [&](std::ostream& os) {
    const auto start = os.tellp();
    os << PcdHeader(0, true);
    auto put = [&](const PointCloud& c) {
      c.CheckConsistent(path);
      WriteRecords(os, c);
      n += c.size();
    };
    if (voxel_m > 0) {
      TileSpill spill(path + ".tiles-" + std::to_string(::getpid()), voxel_m);
      parts([&](PointCloud&& p) { spill.Add(p); });
      spill.ForEachTile([&](PointCloud&& t) { put(t.empty() ? t : geometry::VoxelDownsample(t, voxel_m, threads)); });
    } else {
      parts([&](PointCloud&& p) { put(p); });
    }
    const auto end = os.tellp();
    os.seekp(start);
    os << PcdHeader(n, true);
    os.seekp(end);
  });
  return n;
}

void WriteLabelledCloud(const std::string& path, const PointCloud& cloud) {
  cloud.CheckConsistent(path);
  if (EndsWith(path, ".pcd")) {
    WriteLabelledPcd(path, cloud);
  } else if (EndsWith(path, ".ply")) {
    io::WritePly(path, cloud);
  } else {
    throw Error(path + ": output must end in .pcd or .ply");
  }
}

namespace {

constexpr double kRadToDeg = 180.0 / M_PI;
const char* const kObjectColumns =
    "id,session,reference,class,change,partner,move_candidates,alike_beside,exists_in,track,track_sessions,points,"
    "confidence,cx,cy,cz,min_x,min_y,min_z,max_x,max_y,max_z,box_cx,box_cy,box_cz,yaw_deg,length,width,height,ground_z,"
    "height_above_ground,clearance,range_m,observed_fraction,twin_fraction,attached_fraction,box_seen_fraction,hidden_length";

std::string Joined(const std::vector<int>& v, const char* sep) {
  std::string out;
  for (std::size_t i = 0; i < v.size(); ++i) out += (i ? sep : "") + std::to_string(v[i]);
  return out;
}

void WriteObjectRow(std::ostream& os, const MapObject& o) {
  os << o.id << ',' << o.session << ',' << o.reference << ',' << ToString(o.cls) << ',' << o.change << ','
     << o.partner << ',' << Joined(o.move_candidates, ";") << ',' << o.alike_beside << ',' << o.exists_in << ','
     << o.track << ',' << Joined(o.track_sessions, ";") << ',' << o.points << ',' << o.confidence << ','
     << o.centroid.x() << ',' << o.centroid.y() << ',' << o.centroid.z() << ',' << o.lo.x() << ',' << o.lo.y() << ',' << o.lo.z() << ','
     << o.hi.x() << ',' << o.hi.y() << ',' << o.hi.z() << ',' << o.box_center.x() << ',' << o.box_center.y() << ','
     << o.box_center.z() << ',' << o.yaw_rad * kRadToDeg << ',' << o.size.x() << ',' << o.size.y() << ','
     << o.size.z() << ',' << o.ground_z << ',' << o.height_above_ground << ',' << o.clearance_m << ',' << o.range_m << ','
     << o.observed_fraction << ',' << o.twin_fraction << ',' << o.attached_fraction << ',' << o.box_seen_fraction << ','
     << o.hidden_length_m;
}

// Object `id`'s cloud, relative to the objects folder (objects.json's "cloud").
std::string ObjectCloudPath(int id) {
  char name[64];
  std::snprintf(name, sizeof(name), "clouds/object_%04d.pcd", id);
  return name;
}

// A figure as objects.csv writes it: to the millimetre (3 decimals).
double Mm(double v) { return std::round(v * 1e3) / 1e3; }

void Vec(io::json::Writer& w, const std::string& key, const Eigen::Vector3d& v) {
  w.BeginArray(key).Number(Mm(v.x())).Number(Mm(v.y())).Number(Mm(v.z())).EndArray();
}

void Ints(io::json::Writer& w, const std::string& key, const std::vector<int>& v) {
  w.BeginArray(key);
  for (const int i : v) w.Int(i);
  w.EndArray();
}

void WriteObjectJson(io::json::Writer& w, const MapObject& o) {
  w.BeginObject().Int("id", o.id).Int("session", o.session).Int("reference", o.reference);
  w.String("class", ToString(o.cls)).String("change", o.change).Int("partner", o.partner);
  Ints(w, "move_candidates", o.move_candidates);
  w.Int("alike_beside", o.alike_beside).Number("hidden_length_m", Mm(o.hidden_length_m));
  Ints(w, "exists_in", {o.exists_in});
  w.Int("track", o.track);
  Ints(w, "track_sessions", o.track_sessions);
  w.Int("points", o.points).Number("confidence", Mm(o.confidence));
  Vec(w, "centroid", o.centroid);
  Vec(w, "min", o.lo);
  Vec(w, "max", o.hi);
  w.BeginObject("box");
  Vec(w, "center", o.box_center);
  w.Number("yaw_deg", Mm(o.yaw_rad * kRadToDeg));
  Vec(w, "size", o.size);
  w.EndObject().Number("ground_z", Mm(o.ground_z)).Number("height_above_ground", Mm(o.height_above_ground));
  w.String("cloud", ObjectCloudPath(o.id)).EndObject();
}

}  // namespace

void WriteObjects(const std::string& dir, const std::vector<MapObject>& objects, const std::vector<MapObject>* rejected) {
  io::MakeDirs(dir + "/clouds");
  PointCloud all;
  for (const auto& o : objects) {
    WriteLabelledCloud(dir + "/" + ObjectCloudPath(o.id), o.cloud);
    all.append(o.cloud);
  }
  WriteLabelledCloud(dir + "/objects.ply", all);
  io::WriteFileAtomic(dir + "/objects.csv", [&](std::ostream& os) {
    os << kObjectColumns << '\n' << std::fixed << std::setprecision(3);
    for (const auto& o : objects) WriteObjectRow(os, o), os << '\n';
  });
  io::json::Writer w;
  w.BeginObject().BeginArray("objects");
  for (const auto& o : objects) WriteObjectJson(w, o);
  w.EndArray().EndObject();
  io::WriteFileAtomic(dir + "/objects.json", [&](std::ostream& os) { os << w.str(); });
  if (!rejected) return;
  io::WriteFileAtomic(dir + "/rejected.csv", [&](std::ostream& os) {
    os << kObjectColumns << ",reason\n" << std::fixed << std::setprecision(3);
    for (const auto& o : *rejected) WriteObjectRow(os, o), os << ',' << o.rejected << '\n';
  });
}

std::string FormatLog(const Store& store) {
  std::ostringstream os;
  const auto sessions = store.Sessions();
  const auto kfs = store.Keyframes();
  const StoreTotals t = store.Totals();
  os << "map store " << store.path() << ": " << sessions.size() << " sessions, " << kfs.size()
     << " keyframes, resolution " << store.config().resolution_m << " m\n";
  os << std::left << std::setw(5) << "step" << std::setw(22) << "session" << std::setw(5) << "ref" << std::right
     << std::setw(8) << "kf_new" << std::setw(8) << "kf_chg" << std::setw(11) << "pd_strong" << std::setw(10)
     << "pd_weak" << std::setw(11) << "nd_strong" << std::setw(10) << "nd_weak" << std::setw(11) << "superseded"
     << std::setw(10) << "restored" << std::setw(12) << "points" << std::setw(12) << "bytes" << '\n';
  std::size_t snapshot = 0;
  for (const auto& s : sessions) {
    os << std::left << std::setw(5) << s.order << std::setw(22) << s.name << std::setw(5)
       << (s.reference < 0 ? std::string("-") : std::to_string(s.reference)) << std::right << std::setw(8)
       << s.keyframes_new << std::setw(8) << s.keyframes_changed << std::setw(11) << s.pd_strong << std::setw(10)
       << s.pd_weak << std::setw(11) << s.nd_strong << std::setw(10) << s.nd_weak << std::setw(11) << s.superseded
       << std::setw(10) << s.restored << std::setw(12) << s.points << std::setw(12) << s.bytes << '\n';
    snapshot += s.points * 16;  // binary PCD XYZI
  }
  os << "store file: " << Bytes(t.file_bytes) << " (bases " << Bytes(t.base_bytes) << " for " << t.base_points
     << " points, deltas " << Bytes(t.delta_bytes) << " for " << t.delta_points << " points, stored objects of "
     << t.record_steps << " steps " << Bytes(t.record_bytes) << ")\n";
  os << "full PCD snapshot of every session: " << Bytes(snapshot);
  if (snapshot) os << "; store / snapshots = " << std::fixed << std::setprecision(1) << 100.0 * double(t.file_bytes) / double(snapshot) << " %";
  os << '\n';
  return os.str();
}

}  // namespace ltm::map
