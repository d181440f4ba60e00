// Writes the seed corpora of the harnesses: tiny valid files made with the io writers (and the
// store's blob encoder), one folder per harness under argv[1]. Run by make fuzz (fuzz/run.sh);
// nothing binary is kept in the tree.
#include "ltmapper/io/io.hpp"
#include "ltmapper/map/map.hpp"
#include "ltmapper/removert/removert.hpp"
#include "ltmapper/slam/slam.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace fs = std::filesystem;
using namespace ltm;

namespace {

PointCloud Cloud(int n, bool labels) {
  PointCloud c;
  for (int i = 0; i < n; ++i) {
    c.push_back(0.5f * i, -0.25f * i, 0.1f * i, float(i % 7));
    if (labels) {
      c.cls.push_back(PointClass(i % 7));
      c.session.push_back(std::uint16_t(i % 3));
      c.object.push_back(i % 2 ? i : -1);
    }
  }
  return c;
}

Pose SomePose(int i) {
  Pose p = Pose::Identity();
  p.rotate(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitZ()));
  p.translation() = Eigen::Vector3d(1.0 * i, 0.5 * i, 0.0);
  return p;
}

void Text(const fs::path& p, const std::string& s) { std::ofstream(p) << s; }

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: make_seeds OUT_DIR\n";
    return 2;
  }
  const fs::path out = argv[1];
  for (const char* h : {"pcd", "ply", "g2o", "poses", "kitti_bin", "scd", "config", "blob", "json"})
    fs::create_directories(out / h);

  const PointCloud c3 = Cloud(3, false), c5 = Cloud(5, true);
  io::WritePcd((out / "pcd/ascii.pcd").string(), c3, io::PcdFormat::kAscii);
  io::WritePcd((out / "pcd/binary.pcd").string(), c3, io::PcdFormat::kBinary);
  io::WritePcd((out / "pcd/compressed.pcd").string(), c3, io::PcdFormat::kBinaryCompressed);
  io::WritePcd((out / "pcd/empty.pcd").string(), PointCloud{}, io::PcdFormat::kAscii);

  io::WritePly((out / "ply/plain.ply").string(), c3);
  io::WritePly((out / "ply/labelled.ply").string(), c5);

  io::G2oGraph g;
  for (int i = 0; i < 3; ++i) g.vertices.push_back({i, SomePose(i)});
  for (int i = 0; i + 1 < 3; ++i) {
    Edge e;
    e.from = i;
    e.to = i + 1;
    e.T_from_to = SomePose(i).inverse() * SomePose(i + 1);
    e.has_information = i == 0;
    g.edges.push_back(e);
  }
  io::WriteG2o((out / "g2o/graph.g2o").string(), g);

  std::vector<Pose> poses{SomePose(0), SomePose(1), SomePose(2)};
  std::vector<io::StampedPose> stamped;
  for (int i = 0; i < 3; ++i) stamped.push_back({0.1 * i, poses[i]});
  io::WriteKittiPoses((out / "poses/kitti.txt").string(), poses);
  io::WriteTumPoses((out / "poses/tum.txt").string(), stamped);
  Text(out / "poses/tr.txt", "Tr: 1 0 0 0.5 0 1 0 0 0 0 1 -0.1\n");

  io::WriteKittiBin((out / "kitti_bin/scan.bin").string(), c3);

  Eigen::MatrixXd d(20, 60), s(2, 3);
  for (int r = 0; r < d.rows(); ++r)
    for (int k = 0; k < d.cols(); ++k) d(r, k) = (r * 60 + k) % 9 * 0.5;
  s << 0, 1.5, 2, 3, 4.25, 5;
  io::WriteScd((out / "scd/default.scd").string(), d);
  io::WriteScd((out / "scd/small.scd").string(), s);

  slam::SlamConfig slam_cfg;
  removert::RemovertConfig rm_cfg;
  io::SaveConfigFields((out / "config/slam.yaml").string(), FieldsOf(slam_cfg));
  io::SaveConfigFields((out / "config/removert.yaml").string(), FieldsOf(rm_cfg));
  Text(out / "config/section.yaml", "slam:\n  sc:\n    rings: 20\nother: [1, 2]\n");

  for (const auto& [name, cloud] : {std::pair{"plain", c3}, std::pair{"labelled", c5}}) {
    std::ofstream(out / "blob" / (std::string(name) + ".blob"), std::ios::binary)
        << map::EncodeBlob(cloud, 0.01, 1.0);
  }
  std::ofstream(out / "blob/empty.blob", std::ios::binary) << map::EncodeBlob(PointCloud{}, 0.05, 0.5);

  io::json::Writer report;  // shaped like a stage's report.json
  report.BeginObject().String("stage", "removert").BeginArray("pairs").BeginObject().Int("central", 0).Int("query", 1);
  report.String("dir", "pair_00_01").Number("seconds", 1.25).BeginArray("new_keyframes").Int(3).Int(7).EndArray();
  report.EndObject().EndArray().Bool("ok", true).Null("none").String("text", "a\"b\\c\n\u00e9").EndObject();
  Text(out / "json/report.json", report.str());
  return 0;
}
