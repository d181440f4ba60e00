// Private helpers shared by the io .cpp files (not part of the public API).
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Geometry>

#include <limits>
#include <string>
#include <vector>

namespace ltm::io::detail {

// Tolerance on |q| - 1 and on ||R^T R - I|| for rotations read from text files: larger
// deviations are not rounding but a wrong file.
constexpr double kUnitTolerance = 1e-3;

// Rigid pose from a text rotation: checks it is a rotation within kUnitTolerance (error naming
// file:line otherwise) and projects it onto SO(3) so Isometry3d::inverse() is exact.
Pose PoseFromRt(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const std::string& file,
                std::size_t line);
// Pose from a translation and a quaternion (x y z w order as in TUM / g2o), normalised.
Pose PoseFromQuat(const Eigen::Vector3d& t, double qx, double qy, double qz, double qw,
                  const std::string& file, std::size_t line);
// Splits a line into numbers; throws naming file:line on a token that is not a number.
std::vector<double> ParseNumbers(const std::string& text, const std::string& file, std::size_t line);
// `v` as an int: throws "<what> <v> is not an integer in int range" naming file:line when it is
// NaN, fractional or out of range (casting such a double to int is undefined behaviour).
int IntegerId(double v, const std::string& what, const std::string& file, std::size_t line);
// A point's integer label (session, object) read as a double from record `index` ("vertex" /
// "point" `unit`) of `path`: NaN or a value outside T's range is an error naming the file and
// the record (casting it would be undefined behaviour).
template <class T>
T LabelField(double v, const std::string& path, const char* unit, std::size_t index, const char* name) {
  if (!(v >= double(std::numeric_limits<T>::lowest()) && v <= double(std::numeric_limits<T>::max())))
    throw Error(path + ": " + unit + " " + std::to_string(index) + " has " + name + " " + std::to_string(v) +
                " outside its range");
  return static_cast<T>(v);
}
// A point's class read as a double: one of PointClass's values, else an error as above.
PointClass ClassField(double v, const std::string& path, const char* unit, std::size_t index);
// Formats a double so that it reads back to the same value (shortest of %.15g / %.17g).
std::string FormatDouble(double v);

}  // namespace ltm::io::detail
