// Outputs: labelled PCD / PLY clouds, object tables, the `log` text.
#include "ltmapper/map/files.hpp"

#include "ltmapper/io/io.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iomanip>
#include <ostream>
#include <sstream>

namespace ltm::map {
namespace {

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Binary PCD with x y z intensity (float), class (uchar), session (ushort), object (int).
void WriteLabelledPcd(const std::string& path, const PointCloud& cloud) {
  io::WriteFileAtomic(path, [&](std::ostream& os) {
    const std::size_t n = cloud.size();
    os << "# .PCD v0.7 - Point Cloud Data file format (ltmapper map)\nVERSION 0.7\n"
       << "FIELDS x y z intensity class session object\nSIZE 4 4 4 4 1 2 4\nTYPE F F F F U U I\n"
       << "COUNT 1 1 1 1 1 1 1\nWIDTH " << n << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << n
       << "\nDATA binary\n";
    constexpr std::size_t kStride = 23;
    std::string buf;
    constexpr std::size_t kBatch = 1 << 16;
    for (std::size_t b = 0; b < n; b += kBatch) {
      const std::size_t m = std::min(kBatch, n - b);
      buf.assign(m * kStride, '\0');
      for (std::size_t k = 0; k < m; ++k) {
        const std::size_t i = b + k;
        char* p = &buf[k * kStride];
        std::memcpy(p, &cloud.points[i], 16);
        const std::uint8_t c = cloud.cls.empty() ? 0 : std::uint8_t(cloud.cls[i]);
        const std::uint16_t s = cloud.session.empty() ? 0 : cloud.session[i];
        const std::int32_t o = cloud.object.empty() ? -1 : cloud.object[i];
        std::memcpy(p + 16, &c, 1);
        std::memcpy(p + 17, &s, 2);
        std::memcpy(p + 19, &o, 4);
      }
      os.write(buf.data(), std::streamsize(buf.size()));
    }
  });
}

std::string Bytes(std::size_t b) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.2f MB", double(b) / 1e6);
  return buf;
}

}  // namespace

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
    "id,session,reference,class,change,partner,exists_in,points,confidence,cx,cy,cz,min_x,min_y,min_z,max_x,max_y,"
    "max_z,box_cx,box_cy,box_cz,yaw_deg,length,width,height,ground_z,height_above_ground,clearance,range_m,observed_fraction,twin_fraction,attached_fraction";

void WriteObjectRow(std::ostream& os, const MapObject& o) {
  os << o.id << ',' << o.session << ',' << o.reference << ',' << ToString(o.cls) << ',' << o.change << ','
     << o.partner << ',' << o.exists_in << ',' << o.points << ',' << o.confidence << ',' << o.centroid.x() << ','
     << o.centroid.y() << ',' << o.centroid.z() << ',' << o.lo.x() << ',' << o.lo.y() << ',' << o.lo.z() << ','
     << o.hi.x() << ',' << o.hi.y() << ',' << o.hi.z() << ',' << o.box_center.x() << ',' << o.box_center.y() << ','
     << o.box_center.z() << ',' << o.yaw_rad * kRadToDeg << ',' << o.size.x() << ',' << o.size.y() << ','
     << o.size.z() << ',' << o.ground_z << ',' << o.height_above_ground << ',' << o.clearance_m << ',' << o.range_m << ','
     << o.observed_fraction << ',' << o.twin_fraction << ',' << o.attached_fraction;
}

std::string Vec(const Eigen::Vector3d& v) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(3) << '[' << v.x() << ", " << v.y() << ", " << v.z() << ']';
  return os.str();
}

void WriteObjectJson(std::ostream& os, const MapObject& o) {
  os << "{\"id\": " << o.id << ", \"session\": " << o.session << ", \"reference\": " << o.reference
     << ", \"class\": " << io::json::Quote(ToString(o.cls)) << ", \"change\": " << io::json::Quote(o.change)
     << ", \"partner\": " << o.partner << ", \"exists_in\": [" << o.exists_in << "], \"points\": " << o.points
     << ", \"confidence\": " << o.confidence << ", \"centroid\": " << Vec(o.centroid) << ", \"min\": " << Vec(o.lo)
     << ", \"max\": " << Vec(o.hi) << ", \"box\": {\"center\": " << Vec(o.box_center)
     << ", \"yaw_deg\": " << o.yaw_rad * kRadToDeg << ", \"size\": " << Vec(o.size) << "}, \"ground_z\": " << o.ground_z
     << ", \"height_above_ground\": " << o.height_above_ground << ", \"cloud\": \"clouds/object_"
     << std::setw(4) << std::setfill('0') << o.id << std::setfill(' ') << ".pcd\"}";
}

}  // namespace

void WriteObjects(const std::string& dir, const std::vector<MapObject>& objects, const std::vector<MapObject>* rejected) {
  io::MakeDirs(dir + "/clouds");
  PointCloud all;
  for (const auto& o : objects) {
    char name[64];
    std::snprintf(name, sizeof(name), "/clouds/object_%04d.pcd", o.id);
    WriteLabelledCloud(dir + name, o.cloud);
    all.append(o.cloud);
  }
  WriteLabelledCloud(dir + "/objects.ply", all);
  io::WriteFileAtomic(dir + "/objects.csv", [&](std::ostream& os) {
    os << kObjectColumns << '\n' << std::fixed << std::setprecision(3);
    for (const auto& o : objects) WriteObjectRow(os, o), os << '\n';
  });
  io::WriteFileAtomic(dir + "/objects.json", [&](std::ostream& os) {
    os << std::fixed << std::setprecision(3) << "{\"objects\": [";
    for (std::size_t k = 0; k < objects.size(); ++k) os << (k ? ",\n  " : "\n  "), WriteObjectJson(os, objects[k]);
    os << "\n]}\n";
  });
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
