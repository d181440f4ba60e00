// Round trips for every file format io reads and writes.
#include "ltmapper/io/io.hpp"
#include "test_util.hpp"

#include <cstdint>
#include <gtest/gtest.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cmath>
#include <filesystem>
#include <cstring>
#include <random>

namespace fs = std::filesystem;

namespace ltm {
namespace {

PointCloud RandomCloud(std::size_t n, unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-50.f, 50.f), i(0.f, 255.f);
  PointCloud c;
  for (std::size_t k = 0; k < n; ++k) c.push_back(u(rng), u(rng), u(rng) * 0.1f, i(rng));
  return c;
}

Pose RandomPose(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Pose T = Pose::Identity();
  T.linear() = Eigen::Quaterniond(Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 100.0;
  return T;
}

void ExpectSameCloud(const PointCloud& a, const PointCloud& b, float tol = 0.f) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_NEAR(a.points[k].x, b.points[k].x, tol);
    EXPECT_NEAR(a.points[k].y, b.points[k].y, tol);
    EXPECT_NEAR(a.points[k].z, b.points[k].z, tol);
    EXPECT_NEAR(a.points[k].intensity, b.points[k].intensity, tol);
  }
}

void ExpectSamePose(const Pose& a, const Pose& b, double tol = 1e-9) {
  EXPECT_LT((a.matrix() - b.matrix()).cwiseAbs().maxCoeff(), tol) << a.matrix() << "\nvs\n" << b.matrix();
}

class PcdFormats : public ::testing::TestWithParam<io::PcdFormat> {};

TEST_P(PcdFormats, RoundTripIsExact) {
  test::TempDir tmp;
  const PointCloud c = RandomCloud(1000);
  const std::string path = tmp / "cloud.pcd";
  io::WritePcd(path, c, GetParam());
  io::CloudReadStats st;
  const PointCloud r = io::ReadPcd(path, &st);
  EXPECT_EQ(st.points_in_file, 1000u);
  EXPECT_EQ(st.non_finite_dropped, 0u);
  ExpectSameCloud(c, r);  // ascii is written with 9 significant digits: floats survive exactly
  // Nothing but the file itself is left in the folder (no temporaries).
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.str()), fs::directory_iterator{}), 1);
}

TEST_P(PcdFormats, EmptyCloudRoundTrips) {
  test::TempDir tmp;
  io::WritePcd(tmp / "empty.pcd", PointCloud{}, GetParam());
  io::CloudReadStats st;
  EXPECT_TRUE(io::ReadPcd(tmp / "empty.pcd", &st).empty());
  EXPECT_EQ(st.points_in_file, 0u);
}

INSTANTIATE_TEST_SUITE_P(All, PcdFormats,
                         ::testing::Values(io::PcdFormat::kAscii, io::PcdFormat::kBinary,
                                           io::PcdFormat::kBinaryCompressed));

// A binary PCD read a piece at a time gives ReadPcd's points in order, for pieces that do and do
// not divide the count; an empty file gives no piece; ascii data and a truncated file are errors
// naming the file.
TEST(Pcd, PieceReaderGivesTheFileInPieces) {
  test::TempDir tmp;
  const PointCloud c = RandomCloud(1000);
  io::WritePcd(tmp / "c.pcd", c);
  for (std::size_t piece : {1u, 7u, 1000u, 4096u}) {
    io::PcdPieceReader reader(tmp / "c.pcd");
    PointCloud all, part;
    std::size_t pieces = 0;
    while (reader.Next(piece, &part)) {
      EXPECT_LE(part.size(), piece);
      all.append(part);
      ++pieces;
    }
    EXPECT_EQ(pieces, (c.size() + piece - 1) / piece);
    ASSERT_EQ(all.size(), c.size());
    EXPECT_EQ(std::memcmp(all.points.data(), c.points.data(), c.size() * sizeof(PointXYZI)), 0) << piece;
  }
  io::WritePcd(tmp / "empty.pcd", PointCloud{});
  PointCloud part;
  EXPECT_FALSE(io::PcdPieceReader(tmp / "empty.pcd").Next(10, &part));
  io::WritePcd(tmp / "a.pcd", c, io::PcdFormat::kAscii);
  test::ExpectError([&] { io::PcdPieceReader r(tmp / "a.pcd"); }, {tmp / "a.pcd", "ascii"});
  const std::string bytes = test::ReadText(tmp / "c.pcd");
  test::WriteText(tmp / "cut.pcd", bytes.substr(0, bytes.size() - 100));
  test::ExpectError([&] { io::PcdPieceReader r(tmp / "cut.pcd"); }, {tmp / "cut.pcd"});
}

TEST(Pcd, BinaryIsByteForByteWhatPclWrites) {
  test::TempDir tmp;
  PointCloud c = RandomCloud(777);
  c.cls.assign(c.size(), PointClass::kHD);  // arrays are not part of a PCD
  io::WritePcd(tmp / "ours.pcd", c, io::PcdFormat::kBinary);
  pcl::PointCloud<pcl::PointXYZI> pc;
  for (const auto& p : c.points) {
    pcl::PointXYZI q;
    q.x = p.x;
    q.y = p.y;
    q.z = p.z;
    q.intensity = p.intensity;
    pc.push_back(q);
  }
  ASSERT_EQ(pcl::PCDWriter().writeBinary(tmp / "pcl.pcd", pc), 0);
  EXPECT_EQ(test::ReadText(tmp / "ours.pcd"), test::ReadText(tmp / "pcl.pcd"));
}

// Our ascii and binary_compressed reader and writer against PCL's (which the program no longer
// links): PCL's files with extra fields of several types, a field of COUNT 3 and a NaN point read
// as PCL reads them; our files read by PCL give our points.
TEST(Pcd, AsciiAndCompressedAgreeWithPcl) {
  test::TempDir tmp;
  pcl::PointCloud<pcl::PointXYZINormal> pc;  // x y z intensity normal_x..z curvature (padded)
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-80.f, 80.f);
  for (int k = 0; k < 500; ++k) {
    pcl::PointXYZINormal q;
    q.x = u(rng), q.y = u(rng), q.z = u(rng) * 0.05f, q.intensity = std::abs(u(rng));
    q.normal_x = u(rng), q.normal_y = u(rng), q.normal_z = u(rng), q.curvature = u(rng);
    pc.push_back(q);
  }
  pc[7].x = std::nanf("");
  pc.is_dense = false;
  for (const bool compressed : {false, true}) {
    SCOPED_TRACE(compressed ? "binary_compressed" : "ascii");
    const std::string path = tmp / (compressed ? "pcl_c.pcd" : "pcl_a.pcd");
    ASSERT_EQ(compressed ? pcl::PCDWriter().writeBinaryCompressed(path, pc) : pcl::PCDWriter().writeASCII(path, pc, 9), 0);
    io::CloudReadStats st;
    const PointCloud r = io::ReadPcd(path, &st);
    EXPECT_EQ(st.non_finite_dropped, 1u);
    ASSERT_EQ(r.size(), pc.size() - 1);
    for (std::size_t k = 0, j = 0; k < pc.size(); ++k) {
      if (k == 7) continue;
      EXPECT_EQ(r.points[j].x, pc[k].x);
      EXPECT_EQ(r.points[j].y, pc[k].y);
      EXPECT_EQ(r.points[j].z, pc[k].z);
      EXPECT_EQ(r.points[j].intensity, pc[k].intensity);
      ++j;
    }
  }
  const PointCloud c = RandomCloud(700, 9);
  for (const auto format : {io::PcdFormat::kAscii, io::PcdFormat::kBinaryCompressed}) {
    const std::string path = tmp / "ours.pcd";
    io::WritePcd(path, c, format);
    pcl::PointCloud<pcl::PointXYZI> back;
    ASSERT_EQ(pcl::io::loadPCDFile(path, back), 0);
    ASSERT_EQ(back.size(), c.size());
    for (std::size_t k = 0; k < c.size(); ++k) {
      EXPECT_EQ(back[k].x, c.points[k].x);
      EXPECT_EQ(back[k].z, c.points[k].z);
      EXPECT_EQ(back[k].intensity, c.points[k].intensity);
    }
  }
}

TEST(Ply, PartsWriteTheLabelledConcatenation) {
  test::TempDir tmp;
  const PointCloud a = RandomCloud(100), b = RandomCloud(70), empty;
  std::vector<bool> keep(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) keep[i] = i % 3 != 0;
  io::WritePly(tmp / "parts.ply", {{&a, PointClass::kStatic, 0, -1, &keep},
                                   {&empty, PointClass::kHD, 0},
                                   {&b, PointClass::kPDStrong, 2, 1}});
  // The same points built as one labelled cloud.
  PointCloud want;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (keep[i]) {
      want.points.push_back(a.points[i]);
      want.cls.push_back(PointClass::kStatic);
      want.session.push_back(0);
      want.object.push_back(-1);
    }
  for (const auto& p : b.points) {
    want.points.push_back(p);
    want.cls.push_back(PointClass::kPDStrong);
    want.session.push_back(2);
    want.object.push_back(1);
  }
  io::WritePly(tmp / "want.ply", want);
  EXPECT_EQ(test::ReadText(tmp / "parts.ply"), test::ReadText(tmp / "want.ply"));
  const PointCloud r = io::ReadPly(tmp / "parts.ply");
  ASSERT_EQ(r.size(), want.size());
  EXPECT_EQ(r.cls, want.cls);
  EXPECT_EQ(r.object, want.object);
  // A mask of the wrong length is an error naming the file; nothing is written.
  std::vector<bool> short_mask(5, true);
  EXPECT_THROW(io::WritePly(tmp / "bad.ply", {{&a, PointClass::kStatic, 0, -1, &short_mask}}), Error);
  EXPECT_FALSE(fs::exists(tmp / "bad.ply"));
}

TEST(Pcd, XyzOnlyAndDoubleFieldsRead) {
  test::TempDir tmp;
  test::WriteText(tmp / "xyz.pcd",
                  "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
                  "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1.5 2 3\n-4 5 6.25\n");
  const PointCloud c = io::ReadPcd(tmp / "xyz.pcd");
  ASSERT_EQ(c.size(), 2u);
  EXPECT_FLOAT_EQ(c.points[1].x, -4.f);
  EXPECT_FLOAT_EQ(c.points[1].z, 6.25f);
  EXPECT_FLOAT_EQ(c.points[0].intensity, 0.f);
}

// Binary PCDs as drivers write them: extra fields around x y z (a 2-byte ring), fields out of
// order, a NaN point; and double x y z, which take the general reader.
TEST(Pcd, BinaryWithExtraFieldsOrderAndNaN) {
  test::TempDir tmp;
  struct Rec {
    float t, x, y, z;
    std::uint16_t ring;
    float intensity;
  };
  auto bytes = [](const void* p, std::size_t n) { return std::string(static_cast<const char*>(p), n); };
  const Rec recs[3] = {{0.1f, 1.f, 2.f, 3.f, 7, 40.f},
                       {0.2f, std::nanf(""), 5.f, 6.f, 8, 41.f},
                       {0.3f, -7.f, 8.5f, -9.f, 9, 42.f}};
  std::string data;
  for (const Rec& r : recs)
    data += bytes(&r.t, 4) + bytes(&r.x, 4) + bytes(&r.y, 4) + bytes(&r.z, 4) + bytes(&r.ring, 2) +
            bytes(&r.intensity, 4);
  test::WriteText(tmp / "f.pcd",
                  "VERSION 0.7\nFIELDS t x y z ring intensity\nSIZE 4 4 4 4 2 4\nTYPE F F F F U F\n"
                  "COUNT 1 1 1 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA binary\n" + data);
  io::CloudReadStats st;
  const PointCloud c = io::ReadPcd(tmp / "f.pcd", &st);
  EXPECT_EQ(st.points_in_file, 3u);
  EXPECT_EQ(st.non_finite_dropped, 1u);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_FLOAT_EQ(c.points[0].x, 1.f);
  EXPECT_FLOAT_EQ(c.points[0].intensity, 40.f);
  EXPECT_FLOAT_EQ(c.points[1].y, 8.5f);
  EXPECT_FLOAT_EQ(c.points[1].z, -9.f);
  EXPECT_FLOAT_EQ(c.points[1].intensity, 42.f);

  std::string ddata;
  const double xyz[2][3] = {{1.25, -2.5, 3.0}, {4.0, 5.5, -6.75}};
  for (const auto& p : xyz) ddata += bytes(p, 24);
  test::WriteText(tmp / "d.pcd",
                  "VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
                  "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA binary\n" + ddata);
  const PointCloud d = io::ReadPcd(tmp / "d.pcd");
  ASSERT_EQ(d.size(), 2u);
  EXPECT_FLOAT_EQ(d.points[0].y, -2.5f);
  EXPECT_FLOAT_EQ(d.points[1].z, -6.75f);
}

// ltmapper's labelled PCDs (live / meta maps: class U1, session U2, object I4 after x y z
// intensity) read back with their labels, a NaN point dropped with its labels; the same from an
// ASCII file (PCL's reader); a class ltmapper does not have is an error naming the point; a
// field named class of another type is some other tool's and is not read.
TEST(Pcd, LabelledCloudsReadBackWithTheirLabels) {
  test::TempDir tmp;
  auto bytes = [](const void* p, std::size_t n) { return std::string(static_cast<const char*>(p), n); };
  const std::string head = "VERSION 0.7\nFIELDS x y z intensity class session object\nSIZE 4 4 4 4 1 2 4\n"
                           "TYPE F F F F U U I\nCOUNT 1 1 1 1 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
                           "POINTS 3\n";
  auto record = [&](float x, std::uint8_t cls, std::uint16_t ses, std::int32_t obj) {
    const float xyzi[4] = {x, 2.f, 3.f, 0.5f};
    return bytes(xyzi, 16) + bytes(&cls, 1) + bytes(&ses, 2) + bytes(&obj, 4);
  };
  const std::uint8_t pd = std::uint8_t(PointClass::kPDStrong), nd = std::uint8_t(PointClass::kNDStrong);
  test::WriteText(tmp / "l.pcd", head + "DATA binary\n" + record(1.f, pd, 3, 17) + record(std::nanf(""), nd, 4, 18) +
                                     record(5.f, nd, 5, -1));
  const PointCloud c = io::ReadPcd(tmp / "l.pcd");
  ASSERT_EQ(c.size(), 2u);
  ASSERT_EQ(c.cls.size(), 2u);
  EXPECT_EQ(c.cls[0], PointClass::kPDStrong);
  EXPECT_EQ(c.cls[1], PointClass::kNDStrong);
  EXPECT_EQ(c.session, (std::vector<std::uint16_t>{3, 5}));
  EXPECT_EQ(c.object, (std::vector<std::int32_t>{17, -1}));

  test::WriteText(tmp / "a.pcd", head + "DATA ascii\n1 2 3 0.5 " + std::to_string(pd) + " 3 17\n4 2 3 0.5 " +
                                     std::to_string(nd) + " 4 18\n5 2 3 0.5 0 5 -1\n");
  const PointCloud a = io::ReadPcd(tmp / "a.pcd");
  ASSERT_EQ(a.cls.size(), 3u);
  EXPECT_EQ(a.cls[1], PointClass::kNDStrong);
  EXPECT_EQ(a.object[2], -1);

  test::WriteText(tmp / "bad.pcd", head + "DATA binary\n" + record(1.f, pd, 3, 17) + record(2.f, 200, 4, 18) +
                                       record(5.f, nd, 5, -1));
  test::ExpectError([&] { io::ReadPcd(tmp / "bad.pcd"); }, {tmp / "bad.pcd", "point 1", "class"});

  std::string foreign;
  for (float v : {1.f, 2.f, 3.f, 40.f}) foreign += bytes(&v, 4);
  test::WriteText(tmp / "f.pcd", "VERSION 0.7\nFIELDS x y z class\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
                                 "WIDTH 1\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA binary\n" + foreign);
  const PointCloud f = io::ReadPcd(tmp / "f.pcd");
  ASSERT_EQ(f.size(), 1u);
  EXPECT_TRUE(f.cls.empty());
}

TEST(KittiBin, RoundTripAndReadCloudDispatch) {
  test::TempDir tmp;
  const PointCloud c = RandomCloud(500, 2);
  io::WriteKittiBin(tmp / "000007.bin", c);
  EXPECT_EQ(fs::file_size(tmp / "000007.bin"), 500u * 16u);
  ExpectSameCloud(c, io::ReadKittiBin(tmp / "000007.bin"));
  ExpectSameCloud(c, io::ReadCloud(tmp / "000007.bin"));
  EXPECT_THROW(io::ReadCloud(tmp / "cloud.xyz"), Error);
}

TEST(Ply, RoundTripWithScalarFields) {
  test::TempDir tmp;
  PointCloud c = RandomCloud(300, 3);
  for (std::size_t k = 0; k < c.size(); ++k) {
    c.cls.push_back(static_cast<PointClass>(k % 7));
    c.session.push_back(static_cast<std::uint16_t>(k % 5));
    c.object.push_back(int(k % 11) - 1);
  }
  io::WritePly(tmp / "c.ply", c);
  const std::string head = test::ReadText(tmp / "c.ply").substr(0, 300);
  EXPECT_NE(head.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(head.find("property uchar class"), std::string::npos);
  EXPECT_NE(head.find("property ushort session"), std::string::npos);
  EXPECT_NE(head.find("property int object"), std::string::npos);
  const PointCloud r = io::ReadPly(tmp / "c.ply");
  ExpectSameCloud(c, r);
  EXPECT_EQ(r.cls, c.cls);
  EXPECT_EQ(r.session, c.session);
  EXPECT_EQ(r.object, c.object);

  // Without optional arrays only x y z intensity are written.
  const PointCloud plain = RandomCloud(10, 4);
  io::WritePly(tmp / "p.ply", plain);
  EXPECT_EQ(test::ReadText(tmp / "p.ply").find("class"), std::string::npos);
  const PointCloud rp = io::ReadPly(tmp / "p.ply");
  ExpectSameCloud(plain, rp);
  EXPECT_TRUE(rp.cls.empty() && rp.session.empty() && rp.object.empty());
}

TEST(Scd, RoundTripAndShapeErrors) {
  test::TempDir tmp;
  const Eigen::MatrixXd d = Eigen::MatrixXd::Random(20, 60).cwiseAbs() * 10.0;
  io::WriteScd(tmp / "000001.scd", d);
  const Eigen::MatrixXd r = io::ReadScd(tmp / "000001.scd");
  EXPECT_EQ((r - d).cwiseAbs().maxCoeff(), 0.0);
  // Wrong shape: a row with 59 values, named with file:line.
  std::string text = test::ReadText(tmp / "000001.scd");
  const auto eol = text.find('\n', text.find('\n') + 1);  // end of line 2
  const auto last_space = text.rfind(' ', eol);
  text.erase(last_space, eol - last_space);
  test::WriteText(tmp / "bad.scd", text);
  try {
    io::ReadScd(tmp / "bad.scd");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.scd:2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(io::ReadScd(tmp / "000001.scd", 21, 60), Error);
}

TEST(Poses, KittiAndTumRoundTrip) {
  test::TempDir tmp;
  std::mt19937 rng(5);
  std::vector<Pose> poses;
  std::vector<io::StampedPose> stamped;
  for (int k = 0; k < 20; ++k) {
    poses.push_back(RandomPose(rng));
    stamped.push_back({0.1 * k + 1e9, poses.back()});
  }
  io::WriteKittiPoses(tmp / "poses.txt", poses);
  const auto rk = io::ReadKittiPoses(tmp / "poses.txt");
  ASSERT_EQ(rk.size(), poses.size());
  for (std::size_t k = 0; k < poses.size(); ++k) ExpectSamePose(rk[k], poses[k]);

  io::WriteTumPoses(tmp / "tum.txt", stamped);
  const auto rt = io::ReadTumPoses(tmp / "tum.txt");
  ASSERT_EQ(rt.size(), stamped.size());
  for (std::size_t k = 0; k < poses.size(); ++k) {
    EXPECT_DOUBLE_EQ(rt[k].stamp, stamped[k].stamp);
    ExpectSamePose(rt[k].pose, poses[k]);
  }
}

TEST(Poses, TransformFormats) {
  std::mt19937 rng(6);
  const Pose T = RandomPose(rng);
  const Eigen::Matrix4d M = T.matrix();
  std::ostringstream m34, m44, calib;
  m34.precision(17);
  m44.precision(17);
  calib.precision(17);
  calib << "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr:";
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      if (r < 3) m34 << M(r, c) << " ";
      if (r < 3) calib << " " << M(r, c);
      m44 << M(r, c) << (c < 3 ? " " : "\n");
    }
    if (r < 3) m34 << "\n";
  }
  calib << "\n";
  ExpectSamePose(io::ParseTransform(m34.str(), "m34"), T);
  ExpectSamePose(io::ParseTransform(m44.str(), "m44"), T);
  ExpectSamePose(io::ParseTransform(calib.str(), "calib.txt"), T);
  test::TempDir tmp;
  test::WriteText(tmp / "rel.txt", m44.str());
  ExpectSamePose(io::ReadTransform(tmp / "rel.txt"), T);
  EXPECT_THROW(io::ParseTransform("1 2 3", "short"), Error);
  EXPECT_THROW(io::ParseTransform("2 0 0 0 0 1 0 0 0 0 1 0", "scaled"), Error);  // not a rotation
}

TEST(G2o, RoundTripWithAndWithoutInformation) {
  test::TempDir tmp;
  std::mt19937 rng(7);
  io::G2oGraph g;
  for (int k = 0; k < 5; ++k) g.vertices.emplace_back(k, RandomPose(rng));
  for (int k = 0; k < 4; ++k) {
    Edge e;
    e.from = k;
    e.to = k + 1;
    e.T_from_to = RandomPose(rng);
    if (k % 2) {
      e.has_information = true;
      Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Random();
      e.information = A * A.transpose() + Matrix6d::Identity();
    }
    g.edges.push_back(e);
  }
  io::WriteG2o(tmp / "g.g2o", g);
  const auto r = io::ReadG2o(tmp / "g.g2o");
  ASSERT_EQ(r.vertices.size(), 5u);
  ASSERT_EQ(r.edges.size(), 4u);
  for (int k = 0; k < 5; ++k) {
    EXPECT_EQ(r.vertices[k].first, k);
    ExpectSamePose(r.vertices[k].second, g.vertices[k].second, 1e-12);
  }
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(r.edges[k].from, k);
    EXPECT_EQ(r.edges[k].to, k + 1);
    EXPECT_EQ(r.edges[k].has_information, g.edges[k].has_information);
    ExpectSamePose(r.edges[k].T_from_to, g.edges[k].T_from_to, 1e-12);
    EXPECT_LT((r.edges[k].information - g.edges[k].information).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(G2o, ScLioSamStyleSixDecimalsAndFix) {
  test::TempDir tmp;
  // As SC-LIO-SAM writes it: 6 decimals (quaternion norm off by ~1e-6), no information, FIX.
  test::WriteText(tmp / "s.g2o",
                  "VERTEX_SE3:QUAT 0 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 1.000000\n"
                  "VERTEX_SE3:QUAT 1 1.000000 0.100000 0.000000 0.000000 0.000000 0.382683 0.923880\n"
                  "FIX 0\n"
                  "EDGE_SE3:QUAT 0 1 1.000000 0.100000 0.000000 0.000000 0.000000 0.382683 0.923880\n");
  const auto g = io::ReadG2o(tmp / "s.g2o");
  ASSERT_EQ(g.vertices.size(), 2u);
  ASSERT_EQ(g.edges.size(), 1u);
  EXPECT_FALSE(g.edges[0].has_information);
  const Eigen::Matrix3d R = g.vertices[1].second.rotation();
  EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-12);  // normalised
  EXPECT_NEAR(Eigen::AngleAxisd(R).angle(), M_PI / 4, 1e-5);
}

// A config struct as modules write them, for the YAML round trip.
struct IoDemoConfig {
  double voxel_m = 0.5;
  int beams = 64;
  double max_range_m = 80.0;
  bool flag = true;
  std::string loss = "cauchy";
  std::vector<double> resolutions = {1.0, 2.0};
  template <class V>
  void Visit(V& v) {
    v("voxel_m", voxel_m, "m", 0.01, 10.0);
    v("lidar.beams", beams, "", 1, 128);
    v("lidar.max_range_m", max_range_m, "m", 1.0, 500.0);
    v("flag", flag);
    v("loss", loss, {"cauchy", "dcs"});
    v("resolutions", resolutions, "deg", 0.1, 5.0);
  }
};

TEST(Yaml, SaveLoadRoundTripNested) {
  test::TempDir tmp;
  IoDemoConfig c;
  c.voxel_m = 0.1;  // not exactly representable: must survive the text
  c.beams = 32;
  c.max_range_m = 120.25;
  c.flag = false;
  c.loss = "dcs";
  c.resolutions = {0.5, 1.5, 3.0};
  io::SaveConfigFields(tmp / "p.yaml", FieldsOf(c));
  const std::string text = test::ReadText(tmp / "p.yaml");
  EXPECT_NE(text.find("lidar:"), std::string::npos) << text;  // nested map for dotted keys
  IoDemoConfig r;
  io::LoadConfig(tmp / "p.yaml", r);
  EXPECT_EQ(r.voxel_m, c.voxel_m);
  EXPECT_EQ(r.beams, 32);
  EXPECT_EQ(r.max_range_m, 120.25);
  EXPECT_FALSE(r.flag);
  EXPECT_EQ(r.loss, "dcs");
  EXPECT_EQ(r.resolutions, c.resolutions);
}

TEST(Yaml, SectionPartialKeysAndFlatDottedKeys) {
  test::TempDir tmp;
  test::WriteText(tmp / "all.yaml",
                  "other:\n  anything: 1\nmine:\n  voxel_m: 0.25\n  lidar.beams: 16\n");
  IoDemoConfig c;
  io::LoadConfig(tmp / "all.yaml", c, "mine");
  EXPECT_EQ(c.voxel_m, 0.25);
  EXPECT_EQ(c.beams, 16);
  EXPECT_EQ(c.max_range_m, 80.0);  // absent: default kept
  IoDemoConfig d;
  io::LoadConfig(tmp / "all.yaml", d, "absent_section");
  EXPECT_EQ(d.voxel_m, 0.5);
}

// io::json: the writer escapes every control character, and Parse reads each string it writes
// back unchanged, and the escapes only readers meet (\/ \b \f); bytes that are not UTF-8 are
// written as U+FFFD.
TEST(Json, WrittenStringsEscapeControlCharactersAndParseReadsThemBack) {
  std::string all;
  for (int c = 1; c < 128; ++c) all += char(c);
  io::json::Writer w;
  w.BeginObject().String("k", all).String("s", "a\"b\\c\nd\x01").String("bad", "a\xff").EndObject();
  test::ExpectContains(w.str(), {"\"a\\\"b\\\\c\\nd\\u0001\"", "\"a\xef\xbf\xbd\""});
  const io::json::Value v = io::json::Parse(w.str(), "test");
  ASSERT_NE(v.Find("k"), nullptr);
  EXPECT_EQ(v.Find("k")->str, all);
  EXPECT_EQ(io::json::Parse("\"\\/\\b\\f\"", "test").str, "/\b\f");
  test::ExpectError([] { io::json::Parse("\"\\x\"", "where"); }, {"where", "offset 3", "after backslash"});
  test::ExpectError([] { io::json::Parse("[1e999]", "big.json"); }, {"big.json", "JSON error"});
  test::ExpectError([] { io::json::Parse("{\"a\": 1} x", "tail.json"); }, {"tail.json", "offset"});
}

// A document nested deeper than the parser allows is an error, not a stack overflow; the writer
// builds what it is told in order and refuses a value outside any container.
TEST(Json, DeepNestingIsAnErrorAndTheWriterKeepsOrder) {
  test::ExpectError([] { io::json::Parse(std::string(100000, '[') + std::string(100000, ']'), "deep.json"); },
                    {"deep.json", "nesting deeper than 256"});
  io::json::Writer w;
  w.BeginObject().Int("z", 1).Number("a", 0.1).Number("nan", std::nan("")).BeginArray("v").Number(2.5).EndArray()
      .String("s", "x\"y").Bool("b", true).EndObject();
  EXPECT_EQ(w.str(), "{\n  \"z\": 1,\n  \"a\": 0.1,\n  \"nan\": null,\n  \"v\": [\n    2.5\n  ],\n  \"s\": \"x\\\"y\",\n"
                     "  \"b\": true\n}\n");
  const io::json::Value v = io::json::Parse(w.str(), "w");
  ASSERT_EQ(v.obj.size(), 6u);
  EXPECT_EQ(v.obj[0].first, "z");
  EXPECT_EQ(v.Find("v")->arr.at(0).num, 2.5);
  io::json::Writer bad;
  test::ExpectError([&] { bad.Number("x", 1.0); }, {"outside any object or array"});
}

}  // namespace
}  // namespace ltm
