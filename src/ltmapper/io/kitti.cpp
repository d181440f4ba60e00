// KITTI velodyne .bin clouds (float32 x y z reflectance, little endian) and ReadCloud dispatch.
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/formats.hpp"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;

namespace ltm::io {

static_assert(sizeof(float) == 4, "KITTI .bin needs 32-bit floats");

PointCloud ReadKittiBin(const std::string& path, CloudReadStats* stats) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw Error(path + ": no such file");
  const std::size_t bytes = std::size_t(fs::file_size(path, ec));
  if (ec) throw Error(path + ": cannot stat: " + ec.message());
  if (bytes % 16 != 0)
    throw Error(path + ": KITTI .bin size " + std::to_string(bytes) +
                " bytes is not a multiple of 16 (x y z reflectance float32): truncated file?");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open");
  std::vector<float> raw(bytes / 4);
  in.read(reinterpret_cast<char*>(raw.data()), std::streamsize(bytes));
  if (std::size_t(in.gcount()) != bytes) throw Error(path + ": short read");
  const std::size_t n = bytes / 16;
  PointCloud cloud;
  cloud.reserve(n);
  std::size_t dropped = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const float* p = &raw[4 * i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]) || !std::isfinite(p[3])) {
      ++dropped;
      continue;
    }
    cloud.push_back(p[0], p[1], p[2], p[3]);
  }
  if (stats) {
    stats->points_in_file = n;
    stats->non_finite_dropped = dropped;
  }
  return cloud;
}

void WriteKittiBin(const std::string& path, const PointCloud& cloud) {
  WriteFileAtomic(path, [&](std::ostream& out) {
    static_assert(sizeof(PointXYZI) == 16, "PointXYZI must be 4 packed floats");
    out.write(reinterpret_cast<const char*>(cloud.points.data()),
              std::streamsize(cloud.points.size() * sizeof(PointXYZI)));
  });
}

PointCloud ReadCloud(const std::string& path, CloudReadStats* stats) {
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".pcd") return ReadPcd(path, stats);
  if (ext == ".bin") return ReadKittiBin(path, stats);
  if (ext == ".ply") {
    PointCloud c = ReadPly(path);
    if (stats) {
      stats->points_in_file = c.size();
      stats->non_finite_dropped = 0;
    }
    return c;
  }
  throw Error(path + ": unknown cloud extension '" + ext + "' (expected .pcd, .bin or .ply)");
}

}  // namespace ltm::io
