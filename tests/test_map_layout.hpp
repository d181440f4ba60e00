// The stage outputs LT-map reads, written small for the map CLI tests (crash, read-only and
// disk-full trials), and the check those tests share.
#pragma once

#include "ltmapper/io/io.hpp"
#include "ltmapper/map/map.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace ltm::test {

inline PointCloud Grid(float x0, float y0, float z, int nx, int ny, float step) {
  PointCloud c;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j) c.push_back(x0 + i * step, y0 + j * step, z, 0.3f);
  return c;
}

inline std::string Index6(int k) {
  char b[16];
  std::snprintf(b, sizeof(b), "%06d", k);
  return b;
}

// A small LT-SLAM + LT-removert output: central session_00 with `n` keyframes 5 m apart on a line,
// query session_01 with per-keyframe PD / ND and two new-territory keyframes.
inline void WriteLayout(const std::string& root, int n) {
  const std::string aligned = root + "/aligned", changes = root + "/changes", pair = changes + "/pair_00_01";
  std::vector<Pose> p0, p1;
  for (int k = 0; k < n; ++k) {
    Pose T = Pose::Identity();
    T.translation() = Eigen::Vector3d(5.0 * k, 0, 0);
    p0.push_back(T);
    T.translation().y() = 0.5;
    p1.push_back(T);
  }
  io::MakeDirs(aligned + "/session_00");
  io::MakeDirs(aligned + "/session_01");
  io::WriteKittiPoses(aligned + "/session_00/poses_world.txt", p0);
  io::WriteKittiPoses(aligned + "/session_01/poses_world.txt", p1);
  io::WriteFileAtomic(pair + "/keyframes.csv", [&](std::ostream& os) {
    os << "kind,session,index,static,hd,pd_strong,pd_weak,nd_strong,nd_weak,r00,r01,r02,tx,r10,r11,r12,ty,r20,r21,r22,tz\n";
    for (int k = 0; k < n; ++k) os << "central,0," << k << ",0,0,0,0,0,0,1,0,0," << 5.0 * k << ",0,1,0,0,0,0,1,0\n";
    for (int j = 0; j < 2; ++j) os << "new,1," << 100 + j << ",0,0,0,0,0,0,1,0,0," << 500.0 + 40 * j << ",0,1,0,0,0,0,1,0\n";
  });
  for (int k = 0; k < n; ++k) {
    const std::string d = pair + "/keyframes/" + Index6(k) + "/";
    io::MakeDirs(d);
    PointCloud st = Grid(-2.5f, -10, 0, 25, 100, 0.2f);  // 2500 ground points
    st.append(Grid(-2.5f, 8, 1, 25, 10, 0.2f));          // a low wall
    io::WritePcd(d + "static.pcd", st);
    io::WritePcd(d + "nd_strong.pcd", Grid(-2.5f, 8, 1, 25, 5, 0.2f));
    io::WritePcd(d + "nd_weak.pcd", Grid(-2.5f, -10, 0, 5, 5, 0.2f));
    io::WritePcd(d + "pd_strong.pcd", Grid(-2.5f, 3, 2, 25, 4, 0.2f));
    io::WritePcd(d + "pd_weak.pcd", k % 3 ? PointCloud{} : Grid(0, 0, 0.5f, 10, 20, 0.2f));
  }
  for (int j = 0; j < 2; ++j) {
    const std::string d = pair + "/new_keyframes/" + Index6(100 + j) + "/";
    io::MakeDirs(d);
    io::WritePcd(d + "pd_strong.pcd", Grid(-10, -10, 0, 50, 50, 0.4f));
    io::WritePcd(d + "pd_weak.pcd", Grid(0, 0, 0.5f, 10, 20, 0.2f));
  }
}

inline std::uint64_t DigestOf(const std::string& path, bool* fsck_ok) {
  const map::Store s = map::Store::Open(path);
  const map::FsckReport r = s.Fsck();
  *fsck_ok = r.ok;
  for (const auto& p : r.problems) ADD_FAILURE() << path << ": " << p;
  return s.Digest();
}

}  // namespace ltm::test
