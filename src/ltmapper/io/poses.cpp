// Trajectory files: KITTI (12 numbers per line, row-major [R|t]), TUM (stamp t q), and single
// rigid transforms (3x4 / 4x4 text, KITTI calib "Tr:" lines).
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/formats.hpp"
#include "detail.hpp"

#include <Eigen/SVD>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>

namespace ltm::io {
namespace detail {

Pose PoseFromRt(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const std::string& file,
                std::size_t line) {
  if (!R.allFinite() || !t.allFinite()) throw Error(file, line, "pose has non-finite values");
  const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (err > kUnitTolerance || R.determinant() < 0.0) {
    throw Error(file, line,
                "not a rotation matrix (||R^T R - I|| = " + FormatDouble(err) +
                    ", det = " + FormatDouble(R.determinant()) + ")");
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Pose T = Pose::Identity();
  T.linear() = svd.matrixU() * svd.matrixV().transpose();
  T.translation() = t;
  return T;
}

Pose PoseFromQuat(const Eigen::Vector3d& t, double qx, double qy, double qz, double qw,
                  const std::string& file, std::size_t line) {
  Eigen::Quaterniond q(qw, qx, qy, qz);
  if (!t.allFinite() || !q.coeffs().allFinite()) throw Error(file, line, "pose has non-finite values");
  const double n = q.norm();
  if (std::abs(n - 1.0) > kUnitTolerance)
    throw Error(file, line, "quaternion norm " + FormatDouble(n) + " is not 1 (tolerance 1e-3)");
  q.normalize();
  Pose T = Pose::Identity();
  T.linear() = q.toRotationMatrix();
  T.translation() = t;
  return T;
}

std::vector<double> ParseNumbers(const std::string& text, const std::string& file, std::size_t line) {
  std::vector<double> out;
  std::istringstream ss(text);
  for (std::string tok; ss >> tok;) {
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0' || errno == ERANGE)
      throw Error(file, line, "'" + tok + "' is not a number");
    out.push_back(v);
  }
  return out;
}

int IntegerId(double v, const std::string& what, const std::string& file, std::size_t line) {
  constexpr double lo = std::numeric_limits<int>::min(), hi = std::numeric_limits<int>::max();
  if (!(v >= lo && v <= hi) || v != std::trunc(v))
    throw Error(file, line, what + " " + FormatDouble(v) + " is not an integer in int range");
  return int(v);
}

PointClass ClassField(double v, const std::string& path, const char* unit, std::size_t index) {
  if (!(v >= 0 && v <= double(PointClass::kNDWeak)) || v != std::trunc(v))  // NaN fails too
    throw Error(path + ": " + unit + " " + std::to_string(index) + " has unknown class " + std::to_string(v));
  return static_cast<PointClass>(int(v));
}

std::string FormatDouble(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.15g", v);
  if (std::strtod(buf, nullptr) != v) std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

}  // namespace detail

namespace {
std::ifstream OpenText(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open (no such file or not readable)");
  return in;
}

bool IsBlankOrComment(const std::string& line) {
  const auto p = line.find_first_not_of(" \t\r");
  return p == std::string::npos || line[p] == '#';
}

Pose PoseFromRowMajor(const std::vector<double>& v, const std::string& file, std::size_t line) {
  Eigen::Matrix3d R;
  R << v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10];
  return detail::PoseFromRt(R, Eigen::Vector3d(v[3], v[7], v[11]), file, line);
}

void WriteRowMajor(std::ostream& out, const Pose& T) {
  const Eigen::Matrix<double, 3, 4> M = T.matrix().topRows<3>();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) out << (r || c ? " " : "") << detail::FormatDouble(M(r, c));
  out << "\n";
}
}  // namespace

// Calls `row(numbers, line)` for every non-blank, non-comment line of a pose text file, after
// checking it holds exactly `count` numbers (`layout` names them in the error).
template <class Row>
void ForEachPoseLine(const std::string& path, std::size_t count, const char* what, const char* layout,
                     Row&& row) {
  auto in = OpenText(path);
  std::string line;
  std::size_t lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (IsBlankOrComment(line)) continue;
    const auto v = detail::ParseNumbers(line, path, lineno);
    if (v.size() != count)
      throw Error(path, lineno, std::string(what) + " line has " + std::to_string(v.size()) +
                                    " numbers, expected " + std::to_string(count) + " (" + layout + ")");
    row(v, lineno);
  }
}

std::vector<Pose> ReadKittiPoses(const std::string& path) {
  std::vector<Pose> poses;
  ForEachPoseLine(path, 12, "KITTI pose", "row-major 3x4", [&](const std::vector<double>& v, std::size_t lineno) {
    poses.push_back(PoseFromRowMajor(v, path, lineno));
  });
  return poses;
}

void WriteKittiPoses(const std::string& path, const std::vector<Pose>& poses) {
  WriteFileAtomic(path, [&](std::ostream& out) {
    for (const auto& T : poses) WriteRowMajor(out, T);
  });
}

std::vector<double> ReadTimes(const std::string& path) {
  std::vector<double> times;
  ForEachPoseLine(path, 1, "time", "one timestamp in seconds", [&](const std::vector<double>& v, std::size_t lineno) {
    if (!times.empty() && !(v[0] > times.back()))
      throw Error(path, lineno, "times must increase (" + detail::FormatDouble(v[0]) + " after " +
                                    detail::FormatDouble(times.back()) + ")");
    times.push_back(v[0]);
  });
  return times;
}

void WriteTimes(const std::string& path, const std::vector<double>& times) {
  WriteFileAtomic(path, [&](std::ostream& out) {
    for (double t : times) out << detail::FormatDouble(t) << "\n";
  });
}

std::vector<StampedPose> ReadTumPoses(const std::string& path) {
  std::vector<StampedPose> poses;
  ForEachPoseLine(path, 8, "TUM", "stamp tx ty tz qx qy qz qw", [&](const std::vector<double>& v, std::size_t lineno) {
    StampedPose sp;
    sp.stamp = v[0];
    sp.pose = detail::PoseFromQuat({v[1], v[2], v[3]}, v[4], v[5], v[6], v[7], path, lineno);
    poses.push_back(sp);
  });
  return poses;
}

void WriteTumPoses(const std::string& path, const std::vector<StampedPose>& poses) {
  WriteFileAtomic(path, [&](std::ostream& out) {
    for (const auto& sp : poses) {
      const Eigen::Quaterniond q(sp.pose.rotation());
      const Eigen::Vector3d t = sp.pose.translation();
      out << detail::FormatDouble(sp.stamp);
      for (double v : {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()})
        out << " " << detail::FormatDouble(v);
      out << "\n";
    }
  });
}

Pose ParseTransform(const std::string& text, const std::string& where) {
  // A labelled "Tr:" line wins (KITTI calib.txt has P0..P3 too); otherwise every number counts.
  std::istringstream in(text);
  std::string line;
  std::size_t lineno = 0, first_line = 0;
  std::vector<double> all;
  while (std::getline(in, line)) {
    ++lineno;
    if (IsBlankOrComment(line)) continue;
    const auto colon = line.find(':');
    if (colon != std::string::npos) {
      const std::string label = line.substr(line.find_first_not_of(" \t"), colon - line.find_first_not_of(" \t"));
      if (label == "Tr" || label == "Tr_velo_cam" || label == "Tr_velo_to_cam") {
        const auto v = detail::ParseNumbers(line.substr(colon + 1), where, lineno);
        if (v.size() != 12 && v.size() != 16)
          throw Error(where, lineno, label + " has " + std::to_string(v.size()) + " numbers, expected 12 or 16");
        return PoseFromRowMajor(v, where, lineno);
      }
      continue;  // other labelled lines (P0:, R0_rect: ...) are not the transform
    }
    if (!first_line) first_line = lineno;
    const auto v = detail::ParseNumbers(line, where, lineno);
    all.insert(all.end(), v.begin(), v.end());
  }
  if (all.size() == 16) {
    const double e = std::abs(all[12]) + std::abs(all[13]) + std::abs(all[14]) + std::abs(all[15] - 1.0);
    if (e > detail::kUnitTolerance)
      throw Error(where, first_line, "4x4 transform: last row is not [0 0 0 1]");
  } else if (all.size() != 12) {
    throw Error(where, first_line, "expected a 3x4 (12 numbers) or 4x4 (16 numbers) transform, found " +
                                       std::to_string(all.size()) + " numbers");
  }
  return PoseFromRowMajor(all, where, first_line);
}

Pose ReadTransform(const std::string& path) {
  auto in = OpenText(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ParseTransform(ss.str(), path);
}

}  // namespace ltm::io
