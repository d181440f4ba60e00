// Bad input: every reader names the file (and line) and never returns partial data.
#include "ltmapper/io/io.hpp"
#include "test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>

namespace fs = std::filesystem;

namespace ltm {
namespace {

PointCloud Line(std::size_t n) {
  PointCloud c;
  for (std::size_t k = 0; k < n; ++k) c.push_back(float(k), 1.f, 2.f, 3.f);
  return c;
}

TEST(BadInput, MissingFiles) {
  test::TempDir tmp;
  const std::string missing = tmp / "nope.pcd";
  test::ExpectError([&] { io::ReadPcd(missing); }, {missing});
  test::ExpectError([&] { io::ReadKittiBin(tmp / "nope.bin"); }, {"nope.bin"});
  test::ExpectError([&] { io::ReadKittiPoses(tmp / "poses.txt"); }, {"poses.txt"});
  test::ExpectError([&] { io::ReadG2o(tmp / "g.g2o"); }, {"g.g2o"});
  test::ExpectError([&] { io::ReadScd(tmp / "1.scd"); }, {"1.scd"});
  test::ExpectError([&] { io::LoadSession(tmp / "no_session"); }, {"no_session", "no such"});
}

TEST(BadInput, TruncatedBinaryPcd) {
  for (auto fmt : {io::PcdFormat::kBinary, io::PcdFormat::kBinaryCompressed}) {
    test::TempDir tmp;
    io::WritePcd(tmp / "c.pcd", Line(1000), fmt);
    fs::resize_file(tmp / "c.pcd", fs::file_size(tmp / "c.pcd") - 100);
    test::ExpectError([&] { io::ReadPcd(tmp / "c.pcd"); }, {tmp / "c.pcd", "truncated"});
  }
}

TEST(BadInput, TruncatedAsciiPcd) {
  test::TempDir tmp;
  io::WritePcd(tmp / "a.pcd", Line(100), io::PcdFormat::kAscii);
  std::string text = test::ReadText(tmp / "a.pcd");
  text.resize(text.size() - 40);  // cuts the last rows (and one in the middle of its values)
  test::WriteText(tmp / "a.pcd", text);
  test::ExpectError([&] { io::ReadPcd(tmp / "a.pcd"); }, {"a.pcd"});
  // Whole rows missing.
  test::WriteText(tmp / "b.pcd",
                  "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
                  "WIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n1 2 3 4\n5 6 7 8\n");
  test::ExpectError([&] { io::ReadPcd(tmp / "b.pcd"); }, {"b.pcd", "truncated", "3 points"});
}

TEST(BadInput, PcdHeaderDisagreesWithData) {
  test::TempDir tmp;
  // POINTS says 5, WIDTH*HEIGHT says 3.
  test::WriteText(tmp / "p.pcd",
                  "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                  "WIDTH 3\nHEIGHT 1\nPOINTS 5\nDATA ascii\n1 2 3\n4 5 6\n7 8 9\n");
  test::ExpectError([&] { io::ReadPcd(tmp / "p.pcd"); }, {"p.pcd", "POINTS"});
  // Binary data holding more points than the header announces.
  io::WritePcd(tmp / "b.pcd", Line(10), io::PcdFormat::kBinary);
  std::string text = test::ReadText(tmp / "b.pcd");
  for (const char* key : {"WIDTH 10", "POINTS 10"}) {
    const auto p = text.find(key);
    ASSERT_NE(p, std::string::npos);
    text.replace(p, std::string(key).size(), std::string(key).substr(0, std::string(key).size() - 2) + "8");
  }
  test::WriteText(tmp / "b.pcd", text);
  test::ExpectError([&] { io::ReadPcd(tmp / "b.pcd"); }, {"b.pcd", "disagrees"});
  // A trailing newline after binary data (some writers add one) is not a disagreement.
  io::WritePcd(tmp / "nl.pcd", Line(10), io::PcdFormat::kBinary);
  test::WriteText(tmp / "nl.pcd", test::ReadText(tmp / "nl.pcd") + "\n");
  EXPECT_EQ(io::ReadPcd(tmp / "nl.pcd").size(), 10u);
  // More ascii rows than POINTS.
  test::WriteText(tmp / "c.pcd",
                  "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                  "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n4 5 6\n");
  test::ExpectError([&] { io::ReadPcd(tmp / "c.pcd"); }, {"c.pcd", "disagrees"});
  // No x y z.
  test::WriteText(tmp / "d.pcd",
                  "VERSION 0.7\nFIELDS a b\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\n"
                  "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2\n");
  test::ExpectError([&] { io::ReadPcd(tmp / "d.pcd"); }, {"d.pcd", "x y z"});
  // Not a PCD at all.
  test::WriteText(tmp / "e.pcd", "hello\n");
  test::ExpectError([&] { io::ReadPcd(tmp / "e.pcd"); }, {"e.pcd"});
}

// A binary PCD header with FIELDS x y z p and the given SIZE / COUNT lines, `points` points and
// `data_bytes` zero bytes of data.
std::string PcdWithFields(const std::string& size, const std::string& count, std::size_t points,
                          std::size_t data_bytes) {
  return "VERSION 0.7\nFIELDS x y z p\nSIZE " + size + "\nTYPE F F F F\nCOUNT " + count + "\nWIDTH " +
         std::to_string(points) + "\nHEIGHT 1\nPOINTS " + std::to_string(points) + "\nDATA binary\n" +
         std::string(data_bytes, '\0');
}

TEST(BadInput, PcdHeaderSizeAndCountAreCheckedBeforeAnyRead) {
  test::TempDir tmp;
  const std::string f = tmp / "f.pcd";
  // Audit cases: SIZE -12 once wrapped the point step to 0 (segfault), -8 read 10 points out of bounds.
  test::WriteText(f, PcdWithFields("4 4 4 -12", "1 1 1 1", 1000, 0));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "SIZE -12", "'p'"});
  test::WriteText(f, PcdWithFields("4 4 4 -8", "1 1 1 1", 10, 80));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "SIZE -8"});
  test::WriteText(f, PcdWithFields("4 4 4 0", "1 1 1 1", 10, 120));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "SIZE 0"});
  test::WriteText(f, PcdWithFields("4 4 4 3", "1 1 1 1", 10, 150));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "SIZE 3"});
  test::WriteText(f, PcdWithFields("4 4 4 4", "1 1 1 -1", 10, 120));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "COUNT -1", "'p'"});
  test::WriteText(f, PcdWithFields("4 4 4 4", "1 1 1 0", 10, 120));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "COUNT 0"});
  test::WriteText(f, PcdWithFields("4 4 4 4", "1 1 1 4000000000", 10, 160));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "COUNT 4000000000"});
  // Point counts whose byte size overflows 64 bits, or that the file cannot hold.
  test::WriteText(f, PcdWithFields("4 4 4 4", "1 1 1 1", std::size_t(1) << 62, 160));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "truncated"});
  test::WriteText(f, "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4294967296\n"
                     "HEIGHT 4294967296\nDATA binary\n");
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "WIDTH*HEIGHT"});
  // A point step that does not match the data (16 bytes a point announced, 12 present).
  test::WriteText(f, PcdWithFields("4 4 4 4", "1 1 1 1", 10, 120));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "truncated"});
  // Compressed: 8 bytes cannot decompress to 16 MB.
  std::string c = "VERSION 0.7\nFIELDS x y z p\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 1048576\n"
                  "HEIGHT 1\nPOINTS 1048576\nDATA binary_compressed\n";
  const std::uint32_t sizes[2] = {8, 16u << 20};
  c.append(reinterpret_cast<const char*>(sizes), 8);
  c.append(8, '\0');
  test::WriteText(f, c);
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "cannot hold"});
}

// fuzz/fuzz_pcd (out-of-memory): a COUNT (or SIZE) token that is not an integer or overflows
// 64 bits was skipped, so COUNT defaulted to 1 here while PCL's reader took its own value and
// allocated 12 GB for a 3-point ascii file.
TEST(BadInput, FuzzPcdUnparsableSizeOrCountIsAnError) {
  test::TempDir tmp;
  const std::string f = tmp / "f.pcd";
  const std::string huge(51, '1');
  test::WriteText(f, "# .PCD v0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT " + huge +
                         " 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n1 2 3 4\n5 6 7 8\n9 1 2 3\n");
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "bad COUNT value", "111"});
  test::WriteText(f, PcdWithFields("4 4 4 4", "1 1 1 1.5", 1, 16));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "bad COUNT value '1.5'"});
  test::WriteText(f, PcdWithFields("4 4 4 four", "1 1 1 1", 1, 16));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "bad SIZE value 'four'"});
  test::WriteText(f, PcdWithFields("4 4 4 4", "1 1 1 1", 1, 16));  // still read
  EXPECT_EQ(io::ReadPcd(f).size(), 1u);
}

// fuzz/fuzz_pcd (allocation-size-too-big inside pcl::PCDReader::read): 212-byte binary PCDs with
// an 8-byte float x, or without z, went through PCL, which asked for ~100 TB. Uncompressed binary
// files are now always read here (x y z intensity of any type but 8-byte integers).
TEST(BadInput, FuzzPcdBinaryIsNeverReadThroughPcl) {
  test::TempDir tmp;
  const std::string f = tmp / "f.pcd";
  const std::string header =
      "# .P- Point Cloud\nFIELDS x y z intensity\nSIZE 8 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 3\n"
      "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA binary\n";
  const std::string data(
      "\x23\x20\x2e\x20\x30\x2e\x37\x0a\x46\x49\x45\x4c\x44\x53\x1a\x00"
      "\xff\xff\xff\x61\x72\x79\x0a\x39\xff\x78\x20\x79\x20\x7a\x20\x80"
      "\x00\x00\x00\x00\x36\x00\x00\x00\x00\x00\x00\x3f\x00\x00\x80\x20"
      "\x31\x0a\x56\x49\x45\x69\x57\x50\x6e\x74\x65\x6e\x4f\x49\xff\xff"
      "\xff\xff\xff\xbe\xcd",
      69);
  test::WriteText(f, header + data);
  io::CloudReadStats stats;
  const PointCloud c = io::ReadPcd(f, &stats);
  EXPECT_EQ(stats.points_in_file, 3u);
  EXPECT_EQ(c.size() + stats.non_finite_dropped, 3u);
  // Mixed types, read by value: double x, float y, int16 z, uint8 intensity.
  std::string g = "VERSION 0.7\nFIELDS x y z intensity\nSIZE 8 4 2 1\nTYPE F F I U\nCOUNT 1 1 1 1\n"
                  "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n";
  for (int k = 0; k < 2; ++k) {
    const double x = 1.5 + k;
    const float y = -2.25f;
    const std::int16_t z = std::int16_t(-7 + k);
    const std::uint8_t in = std::uint8_t(200 + k);
    g.append(reinterpret_cast<const char*>(&x), 8).append(reinterpret_cast<const char*>(&y), 4);
    g.append(reinterpret_cast<const char*>(&z), 2).append(reinterpret_cast<const char*>(&in), 1);
  }
  test::WriteText(f, g);
  const PointCloud m = io::ReadPcd(f);
  ASSERT_EQ(m.size(), 2u);
  EXPECT_EQ(m.points[1].x, 2.5f);
  EXPECT_EQ(m.points[1].y, -2.25f);
  EXPECT_EQ(m.points[1].z, -6.f);
  EXPECT_EQ(m.points[1].intensity, 201.f);

  // The second find: no z field (the same header otherwise); PCL's reader again asked for ~100 TB.
  std::string no_z = header;
  no_z.replace(no_z.find("FIELDS x y z"), 12, "FIELDS x y r");
  const std::string data3(
      "\x23\x20\xda\x20\xce\xb9\x20\x46\x20\x46\x20\x46\x0a\x43\x4f\x55"
      "\x4e\x54\x20\x51\x20\x30\x20\x30\x20\x30\x0a\xfc\x4f\x49\x4e\x54"
      "\x53\x20\x33\x0a\x44\x41\x54\x41\x20\x62\x69\x6e\x61\x72\x79\x0a"
      "\x23\x20\x2e\x20\xce\xb9\x20\x46\x20\x46\x20\x46\x0a\x43\x4f\x55"
      "\x4e\x54\x20\x31\x20",
      69);
  test::WriteText(f, no_z + data3);
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "no x y z"});
  // 8-byte integers: an error; a field with COUNT 2: its first value, as PCL reads it.
  test::WriteText(f, "VERSION 0.7\nFIELDS x y z\nSIZE 8 4 4\nTYPE I F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
                     "POINTS 1\nDATA binary\n" + std::string(16, '\0'));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "unsupported type"});
  std::string two = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 2 1 1\nWIDTH 1\nHEIGHT 1\n"
                    "POINTS 1\nDATA binary\n";
  for (float v : {1.f, 9.f, 2.f, 3.f}) two.append(reinterpret_cast<const char*>(&v), 4);
  test::WriteText(f, two);
  const PointCloud t = io::ReadPcd(f);
  ASSERT_EQ(t.size(), 1u);
  EXPECT_EQ(t.points[0].x, 1.f);
  EXPECT_EQ(t.points[0].y, 2.f);
  EXPECT_EQ(t.points[0].z, 3.f);
}

// fuzz/fuzz_pcd (SEGV inside pcl::PCDReader::read): a binary_compressed PCD whose FIELDS have no x
// (and a name with NUL bytes). No x y z is now an error before PCL sees the file.
TEST(BadInput, FuzzPcdCompressedWithoutXIsAnError) {
  test::TempDir tmp;
  const std::string f = tmp / "f.pcd";
  const std::string bytes(
      "\x0d\x0a\x0d\x0a\x0d\x0a\x0d\x23\x20\x2e\x50\x43\x44\x20\x76\x30"
      "\x2e\x37\x74\x61\x20\x50\x4f\x49\x4e\x20\x66\x6f\x0a\x56\x45\x52"
      "\x53\x49\x4f\x4e\x20\x30\x2e\x37\x0a\x46\x49\x45\x4c\x44\x53\x20"
      "\x32\x20\x79\x20\x7a\x20\x69\x6e\x74\x65\x6e\x00\x00\x00\x00\x00"
      "\x00\x00\x00\x73\x69\x74\x79\x0a\x53\x49\x5a\x45\x20\x34\x20\x34"
      "\x20\x34\x20\x34\x0a\x54\x59\x50\x45\x20\x46\x20\x46\x20\x46\x20"
      "\x46\x0a\x43\x4f\x55\x4e\x54\x20\x31\x20\x31\x20\x31\x20\x31\x0a"
      "\x57\x49\x44\x54\x48\x20\x33\x0a\x48\x45\x49\x47\x48\x54\x20\x31"
      "\x0a\x56\x49\x45\x57\x50\x4f\x49\x4e\x54\x20\x30\x20\x30\x20\x30"
      "\x20\x31\x20\x30\x20\x30\x20\x30\x0a\x50\x4f\x49\x4e\x54\x53\x20"
      "\x33\x0a\x44\x41\x54\x41\x20\x62\x69\x6e\x61\x72\x79\x5f\x63\x6f"
      "\x6d\x70\x72\x65\x73\x73\x65\x64\x0a\x2c\x00\x00\x00\x30\x00\x00"
      "\x00\x01\x00\x00\x60\x00\x03\x3f\x00\x00\x80\x20\x03\x01\x00\x80"
      "\x20\x02\x00\xbe\x20\x11\x00\xbf\x20\x03\x08\x00\xcd\xcc\xcc\x3d"
      "\xcd\xcc\x4c\x3e\x40\x0b\x20\x17\x20\x1f\x01\x00\x40",
      237);
  test::WriteText(f, bytes);
  test::ExpectError([&] { io::ReadPcd(f); }, {f});  // (its leading "\r\n" lines: see FuzzPcdWhitespaceHeaderLine)
  test::WriteText(f, bytes.substr(bytes.find('#')));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "no x y z", "'x'"});
}

// fuzz/fuzz_pcd (SEGV inside pcl::PCDReader::read): an ascii PCD without a POINTS line (PCL sized
// the data by POINTS, 0, and filled WIDTH*HEIGHT points). Now an error for ascii and
// binary_compressed data; uncompressed binary (read here) still takes WIDTH*HEIGHT.
TEST(BadInput, FuzzPcdWithoutPointsLine) {
  test::TempDir tmp;
  const std::string f = tmp / "f.pcd";
  const std::string bytes(
      "\x0d\x0a\x0d\x0a\x0d\x0a\x0d\x0d\x0a\x0d\x0a\x0d\x0a\x23\x20\x2e"
      "\x20\x30\x2e\x37\x0d\x0a\x0a\x46\x49\x45\x4c\x44\x53\x20\x78\x20"
      "\x79\x20\x7a\x20\x69\x6e\x74\x65\x6e\x73\x69\x74\x79\x0a\x53\x49"
      "\x5a\x45\x20\x34\x20\x34\x20\x0d\x34\x20\x34\x0a\x54\x59\x50\x45"
      "\x20\x46\x20\x46\x20\x46\x20\x46\x0a\x43\x4f\x55\x4e\x54\x20\x31"
      "\x20\x31\x20\x31\x20\x31\x0a\x57\x49\x44\x54\x48\x20\x33\xf7\xa9"
      "\xb6\xba\xa8\x20\x30\x20\x30\x26\x20\x30\xd3\xb0\x31\x20\x30\x20"
      "\x33\x0a\x44\x41\x54\x41\x20\x61\x73\x63\x69\x69\x0a\x30\x20\x2d"
      "\x30\x20\x30\x20\x7a\x30\x0a\x30\x2e\x35\x20\x2d\x30\x35\x20\x30"
      "\xe9\x31\x30\x30\x30\x30\x30\x30\x30\x31\x20\xcb\xcb\xcb\xcb\xcb"
      "\xcb\xcb\xcb\xcb\xcb\xcb\xcb\xcb\xcb\xcb\xcb\xcb\x31\x0a\x31\x20"
      "\x2d\x30\x2e\x35\x20\xfe\xff\xff\xff\xff\xff\xff\xff\x30\x2e\x32"
      "\x30\x30\x30\x30\x30\x30\x30\x33\x20\x32\x0a",
      203);
  test::WriteText(f, bytes);
  test::ExpectError([&] { io::ReadPcd(f); }, {f});  // (its leading "\r\n" lines: see FuzzPcdWhitespaceHeaderLine)
  test::WriteText(f, bytes.substr(bytes.find('#')));
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "no POINTS line", "ascii"});
  test::WriteText(f, "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
                     "DATA ascii\n1 2 3\n4 5 6\n");
  test::ExpectError([&] { io::ReadPcd(f); }, {f, "no POINTS line"});
  test::WriteText(f, "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
                     "DATA binary\n" + std::string(12, '\0'));
  EXPECT_EQ(io::ReadPcd(f).size(), 1u);
}

// fuzz/fuzz_pcd (SEGV inside pcl::PCDReader::read): a header line of only whitespace (" ", "\t",
// "\r" of a CRLF blank line) before a valid ascii or binary_compressed header. An error naming the
// line now; uncompressed binary data (read here) still allows it.
TEST(BadInput, FuzzPcdWhitespaceHeaderLine) {
  test::TempDir tmp;
  const std::string f = tmp / "f.pcd";
  PointCloud c;
  c.push_back(1.f, 2.f, 3.f, 4.f);
  for (auto fmt : {io::PcdFormat::kAscii, io::PcdFormat::kBinaryCompressed, io::PcdFormat::kBinary}) {
    io::WritePcd(f, c, fmt);
    const std::string valid = test::ReadText(f);
    for (const char* blank : {"\r\n", " \n", "\t\n"}) {
      test::WriteText(f, blank + valid);
      if (fmt == io::PcdFormat::kBinary)
        EXPECT_EQ(io::ReadPcd(f).size(), 1u);
      else
        test::ExpectError([&] { io::ReadPcd(f); }, {f + ":1:", "only whitespace"});
    }
    test::WriteText(f, "\n" + valid);  // an empty line is fine
    EXPECT_EQ(io::ReadPcd(f).size(), 1u);
  }
}

TEST(BadInput, G2oIdsOutOfIntRangeAreErrors) {
  test::TempDir tmp;
  const std::string g = tmp / "ids.g2o";
  for (const char* id : {"2.2e16", "1e10", "nan", "-3e9", "1.5"}) {
    test::WriteText(g, std::string("VERTEX_SE3:QUAT ") + id + " 0 0 0 0 0 0 1\n");
    test::ExpectError([&] { io::ReadG2o(g); }, {g + ":1", "vertex id", "not an integer in int range"});
    test::WriteText(g, std::string("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 ") + id +
                           " 0 0 0 0 0 0 1\n");
    test::ExpectError([&] { io::ReadG2o(g); }, {g + ":2", "edge id", "not an integer in int range"});
  }
}

// A binary PLY of `n` stated vertices with float x y z and the float properties `extra`, and
// `body` as data.
std::string PlyText(std::size_t n, const std::vector<std::string>& extra, const std::string& body) {
  std::string h = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) +
                  "\nproperty float x\nproperty float y\nproperty float z\n";
  for (const auto& e : extra) h += "property float " + e + "\n";
  return h + "end_header\n" + body;
}

std::string Floats(std::initializer_list<float> v) {
  return std::string(reinterpret_cast<const char*>(v.begin()), v.size() * sizeof(float));
}

TEST(BadInput, PlyCountsAndIntegerFieldsAreChecked) {
  test::TempDir tmp;
  const std::string f = tmp / "v.ply";
  // 200 M vertices claimed by a tiny file: an error before any allocation (once 2.4 GB, 41 s).
  test::WriteText(f, PlyText(200000000, {}, Floats({1, 2, 3})));
  test::ExpectError([&] { io::ReadPly(f); }, {f, "truncated PLY", "200000000 vertices"});
  test::WriteText(f, PlyText(std::size_t(1) << 62, {}, Floats({1, 2, 3})));
  test::ExpectError([&] { io::ReadPly(f); }, {f, "truncated PLY"});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  test::WriteText(f, PlyText(2, {"class"}, Floats({1, 2, 3, 1, 4, 5, 6, nan})));
  test::ExpectError([&] { io::ReadPly(f); }, {f, "vertex 1", "class"});
  test::WriteText(f, PlyText(1, {"session"}, Floats({1, 2, 3, 1e10f})));
  test::ExpectError([&] { io::ReadPly(f); }, {f, "vertex 0", "session"});
  test::WriteText(f, PlyText(1, {"object"}, Floats({1, 2, 3, nan})));
  test::ExpectError([&] { io::ReadPly(f); }, {f, "vertex 0", "object"});
  // In range: read as before.
  test::WriteText(f, PlyText(1, {"class", "session", "object"}, Floats({1, 2, 3, 2, 7, -1})));
  const PointCloud c = io::ReadPly(f);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(int(c.cls[0]), 2);
  EXPECT_EQ(c.session[0], 7);
  EXPECT_EQ(c.object[0], -1);
}

TEST(BadInput, NonFinitePointsDroppedAndCounted) {
  test::TempDir tmp;
  PointCloud c = Line(10);
  c.points[2].x = std::numeric_limits<float>::quiet_NaN();
  c.points[5].z = std::numeric_limits<float>::infinity();
  c.points[7].intensity = -std::numeric_limits<float>::infinity();
  for (auto fmt : {io::PcdFormat::kAscii, io::PcdFormat::kBinary, io::PcdFormat::kBinaryCompressed}) {
    io::WritePcd(tmp / "n.pcd", c, fmt);
    io::CloudReadStats st;
    const PointCloud r = io::ReadPcd(tmp / "n.pcd", &st);
    EXPECT_EQ(st.points_in_file, 10u);
    EXPECT_EQ(st.non_finite_dropped, 3u);
    ASSERT_EQ(r.size(), 7u);
    for (const auto& p : r.points)
      EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && std::isfinite(p.intensity));
  }
  io::WriteKittiBin(tmp / "n.bin", c);
  io::CloudReadStats st;
  EXPECT_EQ(io::ReadKittiBin(tmp / "n.bin", &st).size(), 7u);
  EXPECT_EQ(st.non_finite_dropped, 3u);
}

TEST(BadInput, TruncatedKittiBin) {
  test::TempDir tmp;
  io::WriteKittiBin(tmp / "t.bin", Line(10));
  fs::resize_file(tmp / "t.bin", 16 * 10 - 3);
  test::ExpectError([&] { io::ReadKittiBin(tmp / "t.bin"); }, {"t.bin", "multiple of 16"});
}

TEST(BadInput, G2oUnknownTagAndBadQuaternion) {
  test::TempDir tmp;
  const std::string v0 = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n";
  test::WriteText(tmp / "tag.g2o", v0 + "VERTEX_XYZ 1 0 0 0\n");
  test::ExpectError([&] { io::ReadG2o(tmp / "tag.g2o"); }, {"tag.g2o:2", "VERTEX_XYZ"});
  test::WriteText(tmp / "q.g2o", v0 + v0 + "VERTEX_SE3:QUAT 1 0 0 0 0 0 0.5 1\n");
  test::ExpectError([&] { io::ReadG2o(tmp / "q.g2o"); }, {"q.g2o:2", "duplicate vertex id 0"});
  test::WriteText(tmp / "q2.g2o", v0 + "VERTEX_SE3:QUAT 1 0 0 0 0 0 0.5 1\n");
  test::ExpectError([&] { io::ReadG2o(tmp / "q2.g2o"); }, {"q2.g2o:2", "quaternion"});
  test::WriteText(tmp / "e.g2o", v0 + "EDGE_SE3:QUAT 0 3 1 0 0 0 0 0 1\n");
  test::ExpectError([&] { io::ReadG2o(tmp / "e.g2o"); }, {"e.g2o:2", "missing vertex 3"});
  test::WriteText(tmp / "n.g2o", v0 + "EDGE_SE3:QUAT 0 0 1 0 0 0 0 0 1 5\n");
  test::ExpectError([&] { io::ReadG2o(tmp / "n.g2o"); }, {"n.g2o:2", "21 information"});
  test::WriteText(tmp / "x.g2o", "VERTEX_SE3:QUAT 0 0 zero 0 0 0 0 1\n");
  test::ExpectError([&] { io::ReadG2o(tmp / "x.g2o"); }, {"x.g2o:1", "'zero'"});
}

TEST(BadInput, PoseFiles) {
  test::TempDir tmp;
  test::WriteText(tmp / "k.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n");
  test::ExpectError([&] { io::ReadKittiPoses(tmp / "k.txt"); }, {"k.txt:2", "12"});
  test::WriteText(tmp / "t.txt", "0 1 2 3 0 0 0 2\n");
  test::ExpectError([&] { io::ReadTumPoses(tmp / "t.txt"); }, {"t.txt:1", "quaternion"});
}

struct SmallConfig {
  double radius_m = 1.0;
  int k = 3;
  std::string mode = "a";
  std::vector<double> list = {1.0};
  template <class V>
  void Visit(V& v) {
    v("search.radius_m", radius_m, "m", 0.1, 10.0);
    v("search.k", k, "", 1, 50);
    v("mode", mode, {"a", "b"});
    v("list", list, "m", 0.0, 5.0);
  }
};

TEST(BadInput, Yaml) {
  test::TempDir tmp;
  SmallConfig c;
  test::ExpectError([&] { io::LoadConfig(tmp / "none.yaml", c); }, {"none.yaml"});
  test::WriteText(tmp / "bad.yaml", "search:\n  radius_m: [1, 2\nmode: a\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "bad.yaml", c); }, {"bad.yaml:"});
  test::WriteText(tmp / "unknown.yaml", "search:\n  radius_m: 2\n  kk: 4\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "unknown.yaml", c); },
              {"unknown.yaml:3", "unknown key 'search.kk'", "search.k"});
  test::WriteText(tmp / "type.yaml", "search:\n  radius_m: far\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "type.yaml", c); }, {"type.yaml:2", "search.radius_m", "number"});
  test::WriteText(tmp / "list.yaml", "search:\n  radius_m: [1, 2]\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "list.yaml", c); }, {"list.yaml:2", "search.radius_m", "list"});
  test::WriteText(tmp / "int.yaml", "search:\n  k: 2.5\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "int.yaml", c); }, {"int.yaml:2", "search.k", "integer"});
  test::WriteText(tmp / "range.yaml", "search:\n  radius_m: 50\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "range.yaml", c); }, {"range.yaml:2", "search.radius_m", "range"});
  test::WriteText(tmp / "choice.yaml", "mode: c\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "choice.yaml", c); }, {"choice.yaml:1", "mode"});
  test::WriteText(tmp / "seq.yaml", "list: 3\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "seq.yaml", c); }, {"seq.yaml:1", "list"});
  test::WriteText(tmp / "map.yaml", "search: 3\n");
  test::ExpectError([&] { io::LoadConfig(tmp / "map.yaml", c); }, {"map.yaml:1", "unknown key 'search'"});
  EXPECT_EQ(c.radius_m, 1.0);  // unknown.yaml set radius_m before its bad key: nothing applied
}

TEST(BadInput, AtomicWriteLeavesNoPartialFile) {
  test::TempDir tmp;
  const std::string path = tmp / "out.txt";
  EXPECT_THROW(io::WriteFileAtomic(path, [](std::ostream& os) {
                 os << "half of the data";
                 throw Error("writer failed");
               }),
               Error);
  EXPECT_FALSE(fs::exists(path));
  EXPECT_TRUE(fs::is_empty(tmp.str()));  // temporary removed too
  // An existing file survives a failed rewrite unchanged.
  io::WriteFileAtomic(path, [](std::ostream& os) { os << "old"; });
  EXPECT_THROW(io::WritePathAtomic(path, [](const std::string& tmp_path) {
                 test::WriteText(tmp_path, "partial");
                 throw Error("writer failed");
               }),
               Error);
  EXPECT_EQ(test::ReadText(path), "old");
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.str()), fs::directory_iterator{}), 1);
}

}  // namespace
}  // namespace ltm
