// PLY, binary little endian, with per-point scalar fields CloudCompare shows: float x y z
// intensity, and when the cloud has them uchar class, ushort session, int object.
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/formats.hpp"

#include "detail.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

namespace fs = std::filesystem;

namespace ltm::io {

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "PLY writer assumes a little-endian host"
#endif

namespace {
template <class T>
void Put(std::string& buf, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  buf.append(b, sizeof(T));
}

// A vertex property's scalar type, resolved from its header name once (not per value).
enum class PlyType { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64, kUnknown };

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kUnknown;
  std::size_t size = 0;
  std::size_t offset = 0;
};

// A PLY header: vertex count, bytes per vertex and the vertex properties.
struct PlyHeader {
  std::size_t n = 0, step = 0;
  std::vector<PlyProperty> props;
};

PlyType ParsePlyType(const std::string& t) {
  if (t == "char" || t == "int8") return PlyType::kInt8;
  if (t == "uchar" || t == "uint8") return PlyType::kUInt8;
  if (t == "short" || t == "int16") return PlyType::kInt16;
  if (t == "ushort" || t == "uint16") return PlyType::kUInt16;
  if (t == "int" || t == "int32") return PlyType::kInt32;
  if (t == "uint" || t == "uint32") return PlyType::kUInt32;
  if (t == "float" || t == "float32") return PlyType::kFloat32;
  if (t == "double" || t == "float64") return PlyType::kFloat64;
  return PlyType::kUnknown;
}

std::size_t PlyTypeSize(PlyType t) {
  switch (t) {
    case PlyType::kInt8: case PlyType::kUInt8: return 1;
    case PlyType::kInt16: case PlyType::kUInt16: return 2;
    case PlyType::kInt32: case PlyType::kUInt32: case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
    case PlyType::kUnknown: break;
  }
  return 0;
}

double PlyValue(const char* p, PlyType t) {
  auto get = [p](auto v) {
    std::memcpy(&v, p, sizeof(v));
    return double(v);
  };
  switch (t) {
    case PlyType::kInt8: return get(std::int8_t{});
    case PlyType::kUInt8: return get(std::uint8_t{});
    case PlyType::kInt16: return get(std::int16_t{});
    case PlyType::kUInt16: return get(std::uint16_t{});
    case PlyType::kInt32: return get(std::int32_t{});
    case PlyType::kUInt32: return get(std::uint32_t{});
    case PlyType::kFloat32: return get(float{});
    case PlyType::kFloat64: case PlyType::kUnknown: break;
  }
  return get(double{});
}

// Header and chunked binary body; `point(i, buf)` appends the record of output point i.
template <class PointFn>
void WritePlyRecords(const std::string& path, std::size_t n, bool has_cls, bool has_ses, bool has_obj,
                     const PointFn& point) {
  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\ncomment ltmapper\nelement vertex " << n
         << "\nproperty float x\nproperty float y\nproperty float z\nproperty float intensity\n";
  if (has_cls) header << "property uchar class\n";
  if (has_ses) header << "property ushort session\n";
  if (has_obj) header << "property int object\n";
  header << "end_header\n";
  WriteFileAtomic(path, [&](std::ostream& out) {
    out << header.str();
    std::string buf;
    const std::size_t chunk = 65536;
    for (std::size_t begin = 0; begin < n; begin += chunk) {
      buf.clear();
      const std::size_t end = std::min(n, begin + chunk);
      for (std::size_t i = begin; i < end; ++i) point(i, buf);
      out.write(buf.data(), std::streamsize(buf.size()));
    }
  });
}

// Bytes from the stream's position to the end of the file (the position is kept).
std::size_t BytesLeft(std::istream& in) {
  const auto here = in.tellg();
  in.seekg(0, std::ios::end);
  const auto end = in.tellg();
  in.seekg(here);
  return here < 0 || end < here ? 0 : std::size_t(end - here);
}

void PutXyzi(std::string& buf, const PointXYZI& p) {
  Put(buf, p.x);
  Put(buf, p.y);
  Put(buf, p.z);
  Put(buf, p.intensity);
}

// The header up to end_header (`in` is left at the first data byte).
PlyHeader ParsePlyHeader(const std::string& path, std::istream& in) {
  std::string line;
  std::size_t lineno = 0;
  std::getline(in, line);
  ++lineno;
  if (line != "ply" && line != "ply\r") throw Error(path, 1, "not a PLY file");
  PlyHeader h;
  bool in_vertex = false, seen_vertex = false, format_ok = false;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ss(line);
    std::string key;
    ss >> key;
    if (key == "end_header") break;
    if (key == "comment" || key == "obj_info" || key.empty()) continue;
    if (key == "format") {
      std::string fmt;
      ss >> fmt;
      if (fmt != "binary_little_endian")
        throw Error(path, lineno, "PLY format '" + fmt + "' not supported (binary_little_endian only)");
      format_ok = true;
    } else if (key == "element") {
      std::string name;
      long long count = -1;
      ss >> name >> count;
      if (name == "vertex") {
        if (count < 0) throw Error(path, lineno, "bad vertex count");
        h.n = std::size_t(count);
        in_vertex = seen_vertex = true;
      } else {
        if (!seen_vertex) throw Error(path, lineno, "PLY element '" + name + "' before 'vertex' is not supported");
        in_vertex = false;  // elements after the vertices (faces ...) are ignored
      }
    } else if (key == "property") {
      if (!in_vertex) continue;
      PlyProperty p;
      std::string type_name;
      ss >> type_name >> p.name;
      if (type_name == "list") throw Error(path, lineno, "list properties on vertices are not supported");
      p.type = ParsePlyType(type_name);
      p.size = PlyTypeSize(p.type);
      if (p.size == 0) throw Error(path, lineno, "unknown PLY property type '" + type_name + "'");
      p.offset = h.step;
      h.step += p.size;
      h.props.push_back(p);
    } else {
      throw Error(path, lineno, "unknown PLY header line '" + line + "'");
    }
  }
  if (!format_ok) throw Error(path + ": PLY header has no format line");
  if (!seen_vertex) throw Error(path + ": PLY has no vertex element");
  return h;
}
}  // namespace

void WritePly(const std::string& path, const PointCloud& cloud) {
  cloud.CheckConsistent(path);
  const bool has_cls = !cloud.cls.empty(), has_ses = !cloud.session.empty(),
             has_obj = !cloud.object.empty();
  WritePlyRecords(path, cloud.size(), has_cls, has_ses, has_obj, [&](std::size_t i, std::string& buf) {
    PutXyzi(buf, cloud.points[i]);
    if (has_cls) Put(buf, static_cast<std::uint8_t>(cloud.cls[i]));
    if (has_ses) Put(buf, cloud.session[i]);
    if (has_obj) Put(buf, cloud.object[i]);
  });
}

void WritePly(const std::string& path, const std::vector<PlyPart>& parts) {
  // Output point -> (part, index in its cloud), walked in order by a cursor.
  std::size_t n = 0;
  for (const PlyPart& part : parts) {
    if (!part.cloud) throw Error(path + ": PLY part without a cloud");
    if (part.keep && part.keep->size() != part.cloud->size())
      throw Error(path + ": PLY part mask has " + std::to_string(part.keep->size()) + " entries for " +
                  std::to_string(part.cloud->size()) + " points");
    n += part.keep ? std::size_t(std::count(part.keep->begin(), part.keep->end(), true)) : part.cloud->size();
  }
  std::size_t p = 0, i = 0;
  WritePlyRecords(path, n, true, true, true, [&](std::size_t, std::string& buf) {
    for (;;) {  // next kept point: skip finished parts and masked-out points
      const PlyPart& part = parts[p];
      if (i >= part.cloud->size()) {
        ++p;
        i = 0;
      } else if (part.keep && !(*part.keep)[i]) {
        ++i;
      } else {
        break;
      }
    }
    const PlyPart& part = parts[p];
    PutXyzi(buf, part.cloud->points[i++]);
    Put(buf, static_cast<std::uint8_t>(part.cls));
    Put(buf, part.session);
    Put(buf, part.object);
  });
}

PointCloud ReadPly(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open (no such file or not readable)");
  const PlyHeader header = ParsePlyHeader(path, in);
  const std::size_t n = header.n, step = header.step;
  const std::vector<PlyProperty>& props = header.props;
  const PlyProperty *px = nullptr, *py = nullptr, *pz = nullptr, *pi = nullptr, *pc = nullptr,
                    *ps = nullptr, *po = nullptr;
  for (const auto& p : props) {
    if (p.name == "x") px = &p;
    if (p.name == "y") py = &p;
    if (p.name == "z") pz = &p;
    if (p.name == "intensity" || p.name == "scalar_intensity") pi = &p;
    if (p.name == "class" || p.name == "scalar_class") pc = &p;
    if (p.name == "session" || p.name == "scalar_session") ps = &p;
    if (p.name == "object" || p.name == "scalar_object") po = &p;
  }
  if (!px || !py || !pz) throw Error(path + ": PLY vertices have no x y z");
  // The stated count against the file's length before allocating (step >= 3: x y z exist).
  const std::size_t have = BytesLeft(in);
  if (n > have / step)
    throw Error(path + ": truncated PLY: " + std::to_string(n) + " vertices of " + std::to_string(step) +
                " bytes, the file holds " + std::to_string(have) + " data bytes");
  std::vector<char> data(n * step);
  in.read(data.data(), std::streamsize(data.size()));
  if (std::size_t(in.gcount()) != data.size())
    throw Error(path + ": truncated PLY: " + std::to_string(n) + " vertices need " +
                std::to_string(data.size()) + " bytes, found " + std::to_string(in.gcount()));
  PointCloud cloud;
  cloud.points.resize(n);
  if (pc) cloud.cls.resize(n);
  if (ps) cloud.session.resize(n);
  if (po) cloud.object.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const char* rec = data.data() + i * step;
    auto& p = cloud.points[i];
    p.x = float(PlyValue(rec + px->offset, px->type));
    p.y = float(PlyValue(rec + py->offset, py->type));
    p.z = float(PlyValue(rec + pz->offset, pz->type));
    p.intensity = pi ? float(PlyValue(rec + pi->offset, pi->type)) : 0.f;
    if (pc) cloud.cls[i] = detail::ClassField(PlyValue(rec + pc->offset, pc->type), path, "vertex", i);
    if (ps)
      cloud.session[i] = detail::LabelField<std::uint16_t>(PlyValue(rec + ps->offset, ps->type), path, "vertex", i, "session");
    if (po)
      cloud.object[i] = detail::LabelField<std::int32_t>(PlyValue(rec + po->offset, po->type), path, "vertex", i, "object");
  }
  return cloud;
}

}  // namespace ltm::io
