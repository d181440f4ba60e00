// PCD reading and writing of our own (ascii, binary, binary_compressed with Debian's liblzf):
// PCL's reader printed an error and sometimes returned partial data on truncated or inconsistent
// files, and its pcl_io library brought 67 shared objects (VTK's 29 among them) into every
// command's start (81 % of `ltmapper --version`'s 95 ms went to the dynamic loader). The header is
// parsed first and the data size checked against it (binary: exact byte count; binary_compressed:
// the two size words; ascii: line and token counts). Non-finite points are dropped and counted,
// never passed on.
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/formats.hpp"

#include "detail.hpp"

#include <lzf.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>

namespace fs = std::filesystem;

namespace ltm::io {
namespace {

// Field datatypes, numbered as PCL's PCLPointField numbers them.
enum Datatypes : std::uint8_t { kInt8 = 1, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

// Most values one PCD field may hold (COUNT): descriptors use a few hundred (VFH 308) to a few
// thousand (shape context 1980); the bound keeps the point step far from overflowing while no
// real file comes near it.
constexpr long long kPcdMaxCount = 1 << 20;
// Largest expansion of PCL's LZF (binary_compressed): a 3-byte back-reference copies at most
// 264 bytes, so a block never decompresses to more than 88 times its size.
constexpr std::size_t kLzfMaxRatio = 88;

struct PcdHeader {
  std::vector<std::string> fields;
  std::vector<long long> sizes, counts;  // checked by CheckFields before any use
  std::vector<char> types;
  long long width = -1, height = -1, points = -1;
  std::string data;            // ascii | binary | binary_compressed
  std::vector<double> viewpoint;  // VIEWPOINT tx ty tz qw qx qy qz (empty when absent)
  std::size_t data_offset = 0; // byte offset of the first data byte
  std::size_t header_lines = 0;
  std::size_t blank_line = 0;  // first header line of only spaces / tabs / CR (0: none)
  std::size_t PointStep() const {
    std::size_t s = 0;
    for (std::size_t i = 0; i < sizes.size(); ++i) s += std::size_t(sizes[i]) * std::size_t(counts[i]);
    return s;
  }
  std::size_t Values() const {
    std::size_t s = 0;
    for (long long c : counts) s += std::size_t(c);
    return s;
  }
};

long long ParseCount(const std::string& path, std::size_t line, const std::string& key,
                     std::istringstream& ss) {
  long long v = -1;
  if (!(ss >> v) || v < 0) throw Error(path, line, "bad " + key + " value in PCD header");
  return v;
}

// Every token of a SIZE / COUNT line: an integer (a token that is not one, or that overflows, is
// an error: skipping it once made PCL's own reading of the header disagree with this one and
// allocate 12 GB for a 3-point file; found by fuzz/fuzz_pcd).
std::vector<long long> ParseInts(const std::string& path, std::size_t line, const std::string& key,
                                 std::istringstream& ss) {
  std::vector<long long> out;
  for (std::string t; ss >> t;) {
    long long v = 0;
    const char* end = t.data() + t.size();
    const auto [ptr, ec] = std::from_chars(t.data(), end, v);
    if (ec != std::errc() || ptr != end)
      throw Error(path, line, "bad " + key + " value '" + t.substr(0, 40) + "' in PCD header (expected integers)");
    out.push_back(v);
  }
  return out;
}

// SIZE, TYPE and COUNT of every field: values the format defines, so the point step is the
// true record size (a negative or zero SIZE once wrapped the step to 0 and let reads run past
// the data).
void CheckFields(const std::string& path, const PcdHeader& h) {
  for (std::size_t i = 0; i < h.fields.size(); ++i) {
    const std::string field = "field '" + h.fields[i] + "'";
    const long long size = h.sizes[i], count = h.counts[i];
    if (size != 1 && size != 2 && size != 4 && size != 8)  // the byte sizes the format defines
      throw Error(path + ": PCD header SIZE " + std::to_string(size) + " of " + field + " (expected 1, 2, 4 or 8)");
    if (count < 1 || count > kPcdMaxCount)
      throw Error(path + ": PCD header COUNT " + std::to_string(count) + " of " + field + " (expected 1.." +
                  std::to_string(kPcdMaxCount) + ")");
    const char type = h.types[i];
    if (type != 'F' && type != 'I' && type != 'U')
      throw Error(path + ": PCD header TYPE '" + std::string(1, type) + "' of " + field + " (expected F, I or U)");
    if (type == 'F' && size != 4 && size != 8)
      throw Error(path + ": PCD header SIZE " + std::to_string(size) + " of float " + field + " (expected 4 or 8)");
  }
}

// One header entry `key` (the rest of its line in `ss`) into h. FIELDS / COLUMNS, SIZE, TYPE,
// COUNT, WIDTH, HEIGHT, POINTS; VERSION is read and ignored; anything else is an error.
void ParseEntry(const std::string& path, std::size_t lineno, const std::string& key, std::istringstream& ss,
                PcdHeader& h) {
  if (key == "VERSION") return;
  if (key == "VIEWPOINT") {
    for (double v; ss >> v;) h.viewpoint.push_back(v);
    if (h.viewpoint.size() != 7) throw Error(path, lineno, "VIEWPOINT needs 7 numbers: tx ty tz qw qx qy qz");
  } else if (key == "FIELDS" || key == "COLUMNS") {
    for (std::string f; ss >> f;) h.fields.push_back(f);
  } else if (key == "SIZE") {
    h.sizes = ParseInts(path, lineno, key, ss);
  } else if (key == "TYPE") {
    for (std::string t; ss >> t;) h.types.push_back(t.empty() ? '?' : t[0]);
  } else if (key == "COUNT") {
    h.counts = ParseInts(path, lineno, key, ss);
  } else if (key == "WIDTH") {
    h.width = ParseCount(path, lineno, key, ss);
  } else if (key == "HEIGHT") {
    h.height = ParseCount(path, lineno, key, ss);
  } else if (key == "POINTS") {
    h.points = ParseCount(path, lineno, key, ss);
  } else {
    throw Error(path, lineno, "unknown PCD header entry '" + key + "'");
  }
}

// The DATA line (its type in `ss`): the data start right after it, or at the end of the file
// when DATA was the last line without a newline (no data at all).
void ParseData(std::size_t lineno, std::istringstream& ss, std::ifstream& in, PcdHeader& h) {
  ss >> h.data;
  const auto pos = in.tellg();
  h.data_offset = pos < 0 ? 0 : std::size_t(pos);
  h.header_lines = lineno;
  if (pos < 0) {
    in.clear();
    in.seekg(0, std::ios::end);
    h.data_offset = std::size_t(in.tellg());
  }
}

// The header's lines up to and including DATA, as written (checked by CheckHeader).
PcdHeader ReadHeaderLines(const std::string& path, std::ifstream& in) {
  PcdHeader h;
  std::string line;
  std::size_t lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const bool raw_empty = line.empty();
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ss(line);
    std::string key;
    if (!(ss >> key)) {
      if (!raw_empty && !h.blank_line) h.blank_line = lineno;
      continue;
    }
    if (key[0] == '#') continue;
    if (key == "DATA") {
      ParseData(lineno, ss, in, h);
      break;
    }
    ParseEntry(path, lineno, key, ss, h);
  }
  return h;
}

// A header's entries against each other: a DATA type, FIELDS with a SIZE, TYPE and COUNT each
// (CheckFields), WIDTH, and POINTS = WIDTH * HEIGHT; HEIGHT 1 and COUNTs 1 where absent.
void CheckHeader(const std::string& path, PcdHeader& h) {
  if (h.data.empty()) throw Error(path + ": not a PCD file (no DATA line in the header)");
  if (h.data != "ascii" && h.data != "binary" && h.data != "binary_compressed")
    throw Error(path, h.header_lines, "unknown PCD DATA type '" + h.data + "'");
  if (h.fields.empty()) throw Error(path + ": PCD header has no FIELDS");
  if (h.counts.empty()) h.counts.assign(h.fields.size(), 1);
  if (h.sizes.size() != h.fields.size() || h.types.size() != h.fields.size() ||
      h.counts.size() != h.fields.size())
    throw Error(path + ": PCD header FIELDS/SIZE/TYPE/COUNT have different lengths");
  CheckFields(path, h);
  if (h.width < 0) throw Error(path + ": PCD header has no WIDTH");
  if (h.height < 0) h.height = 1;
  if (h.height != 0 && h.width > std::numeric_limits<long long>::max() / h.height)
    throw Error(path + ": PCD header WIDTH*HEIGHT " + std::to_string(h.width) + "*" + std::to_string(h.height) +
                " is out of range");
}

// What PCL's reader needs of a header that ours does not (ascii and binary_compressed data are
// read by PCL), then POINTS against WIDTH * HEIGHT.
void CheckPoints(const std::string& path, PcdHeader& h) {
  // PCL's reader (ascii / binary_compressed data) dereferences null on a header line of only
  // whitespace (fuzz/fuzz_pcd: one "\r\n" line before a valid header); binary data is read here.
  if (h.blank_line && h.data != "binary")
    throw Error(path, h.blank_line, "PCD header line of only whitespace (not readable with DATA " + h.data + ")");
  // PCL's reader sizes ascii / binary_compressed data by POINTS (0 when absent) but fills WIDTH*HEIGHT
  // points: without the line it wrote through a null pointer (fuzz/fuzz_pcd). Uncompressed binary
  // data is read here, where WIDTH*HEIGHT stands in for it.
  if (h.points < 0 && h.data != "binary" && h.width * h.height > 0)
    throw Error(path + ": PCD header has no POINTS line (needed with DATA " + h.data + ")");
  if (h.points < 0) h.points = h.width * h.height;
  if (h.points != h.width * h.height)
    throw Error(path + ": PCD header POINTS " + std::to_string(h.points) + " != WIDTH*HEIGHT " +
                std::to_string(h.width * h.height));
}

PcdHeader ParseHeader(const std::string& path, std::ifstream& in) {
  PcdHeader h = ReadHeaderLines(path, in);
  CheckHeader(path, h);
  CheckPoints(path, h);
  return h;
}

// Checks that the data section holds exactly what the header announces.
// f(row, values) for each data row of an ascii PCD (`values` holds its tokens; blank and '#'
// lines skipped), every row checked to hold the header's number of values and the rows counted
// against POINTS: errors name the file and line.
// Positions the stream at the first data byte.
void SeekData(std::ifstream& in, const PcdHeader& h) {
  in.clear();
  in.seekg(std::streamoff(h.data_offset));
}

template <class F>
void ForEachAsciiRow(const std::string& path, std::ifstream& in, const PcdHeader& h, const F& f) {
  SeekData(in, h);
  const std::size_t n = std::size_t(h.points), values = h.Values();
  std::string line;
  std::size_t lineno = h.header_lines, rows = 0;
  while (std::getline(in, line)) {
    ++lineno;
    std::istringstream count(line);
    std::size_t tokens = 0;
    bool comment = false;
    for (std::string t; count >> t;) {
      if (tokens == 0 && t[0] == '#') comment = true;
      ++tokens;
    }
    if (tokens == 0 || comment) continue;
    ++rows;
    if (tokens != values)
      throw Error(path, lineno,
                  "PCD ascii row has " + std::to_string(tokens) + " values, expected " + std::to_string(values) +
                      (rows == n && tokens < values ? " (truncated file?)" : ""));
    if (rows > n) continue;  // counted for the error below
    std::istringstream row(line);
    f(lineno, row);
  }
  if (rows < n)
    throw Error(path + ": truncated PCD: header announces " + std::to_string(n) + " points but the file holds " +
                std::to_string(rows) + " rows");
  if (rows > n)
    throw Error(path + ": PCD header disagrees with data: header announces " + std::to_string(n) +
                " points but the file holds " + std::to_string(rows) + " rows");
}

// The data section checked against the header; ascii rows only when `check_ascii_rows` (ReadPcd
// checks them while it reads them).
void CheckDataSize(const std::string& path, std::ifstream& in, const PcdHeader& h, bool check_ascii_rows) {
  in.clear();
  in.seekg(0, std::ios::end);
  const std::size_t file_size = std::size_t(in.tellg());
  const std::size_t have = file_size >= h.data_offset ? file_size - h.data_offset : 0;
  const std::size_t n = std::size_t(h.points);
  const std::size_t step = h.PointStep();  // >= 1 (CheckFields); counts compared by division: no overflow
  if (h.data == "binary") {
    if (n > have / step)
      throw Error(path + ": truncated PCD: header announces " + std::to_string(n) + " points of " +
                  std::to_string(step) + " bytes but the file holds " + std::to_string(have) + " data bytes");
    const std::size_t want = n * step;
    // A few trailing bytes (a newline some writers add) are tolerated; whole extra points mean
    // the header's count is wrong.
    if (have > want && have - want >= step)
      throw Error(path + ": PCD header disagrees with data: " + std::to_string(n) + " points need " +
                  std::to_string(want) + " bytes but the file holds " + std::to_string(have));
  } else if (h.data == "binary_compressed") {
    if (n == 0) return;
    if (have < 8) throw Error(path + ": truncated PCD: compressed data section is missing");
    std::uint32_t sizes[2] = {0, 0};  // compressed, uncompressed byte counts
    in.seekg(std::streamoff(h.data_offset));
    in.read(reinterpret_cast<char*>(sizes), 8);
    if (n != sizes[1] / step || sizes[1] % step != 0)
      throw Error(path + ": PCD header disagrees with data: " + std::to_string(n) + " points of " +
                  std::to_string(step) + " bytes, the data says " + std::to_string(sizes[1]) +
                  " bytes uncompressed");
    if (have < 8 + std::size_t(sizes[0]))
      throw Error(path + ": truncated PCD: compressed block of " + std::to_string(sizes[0]) +
                  " bytes but only " + std::to_string(have - 8) + " present");
    if (std::size_t(sizes[1]) > std::size_t(sizes[0]) * kLzfMaxRatio)
      throw Error(path + ": corrupt PCD: " + std::to_string(sizes[0]) + " compressed bytes cannot hold " +
                  std::to_string(sizes[1]) + " bytes uncompressed");
  } else {  // ascii: counted while the rows are read (ForEachAsciiRow), by OpenPcd or ReadPcd
    if (check_ascii_rows) ForEachAsciiRow(path, in, h, [](std::size_t, std::istringstream&) {});
  }
}

double ReadValue(const std::uint8_t* p, std::uint8_t datatype) {
  switch (datatype) {
    case kInt8: { std::int8_t v; std::memcpy(&v, p, 1); return v; }
    case kUint8: { std::uint8_t v; std::memcpy(&v, p, 1); return v; }
    case kInt16: { std::int16_t v; std::memcpy(&v, p, 2); return v; }
    case kUint16: { std::uint16_t v; std::memcpy(&v, p, 2); return v; }
    case kInt32: { std::int32_t v; std::memcpy(&v, p, 4); return v; }
    case kUint32: { std::uint32_t v; std::memcpy(&v, p, 4); return v; }
    case kFloat32: { float v; std::memcpy(&v, p, 4); return v; }
    case kFloat64: { double v; std::memcpy(&v, p, 8); return v; }
    default: return std::nan("");
  }
}

// Where a point field lies in a point record: byte offset and PCL datatype; datatype 0 = absent.
struct FieldAt {
  std::size_t offset = 0;
  std::uint8_t datatype = 0;
};
// Raw point records: `rows` rows of `cols` points, `row_step` bytes per row, `point_step` per point.
struct Records {
  const std::uint8_t* data = nullptr;
  std::size_t rows = 0, cols = 0, row_step = 0, point_step = 0;
};

// The optional per-point labels ltmapper's labelled clouds carry (class, session, object).
struct LabelFields {
  FieldAt cls, session, object;
  bool Any() const { return cls.datatype || session.datatype || object.datatype; }
};

// Appends the finite points of `rec` to `cloud` (`value` reads one field value; intensity 0 when
// absent) and, when `kept` is given, each kept point's record number; returns how many were
// dropped as non-finite.
template <class Value>
std::size_t AppendPoints(const Records& rec, FieldAt fx, FieldAt fy, FieldAt fz, FieldAt fi, Value value,
                         PointCloud* cloud, std::vector<std::size_t>* kept) {
  std::size_t dropped = 0;
  for (std::size_t r = 0; r < rec.rows; ++r) {
    const std::uint8_t* row = rec.data + r * rec.row_step;
    for (std::size_t c = 0; c < rec.cols; ++c) {
      const std::uint8_t* p = row + c * rec.point_step;
      const auto x = value(p + fx.offset, fx.datatype);
      const auto y = value(p + fy.offset, fy.datatype);
      const auto z = value(p + fz.offset, fz.datatype);
      const auto in = fi.datatype ? value(p + fi.offset, fi.datatype) : decltype(x)(0);
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z) || !std::isfinite(in)) {
        ++dropped;
        continue;
      }
      cloud->push_back(float(x), float(y), float(z), float(in));
      if (kept) kept->push_back(r * rec.cols + c);
    }
  }
  return dropped;
}

// The labels of the kept records (record numbers `kept`), checked like PLY's (an unknown class,
// a session or object out of range: an error naming the file and the point).
void ReadLabels(const Records& rec, const LabelFields& f, const std::vector<std::size_t>& kept, const std::string& path,
                PointCloud* cloud) {
  if (f.cls.datatype) cloud->cls.resize(kept.size());
  if (f.session.datatype) cloud->session.resize(kept.size());
  if (f.object.datatype) cloud->object.resize(kept.size());
  for (std::size_t k = 0; k < kept.size(); ++k) {
    const std::size_t n = kept[k];
    const std::uint8_t* p = rec.data + (n / rec.cols) * rec.row_step + (n % rec.cols) * rec.point_step;
    if (f.cls.datatype) cloud->cls[k] = detail::ClassField(ReadValue(p + f.cls.offset, f.cls.datatype), path, "point", n);
    if (f.session.datatype)
      cloud->session[k] =
          detail::LabelField<std::uint16_t>(ReadValue(p + f.session.offset, f.session.datatype), path, "point", n, "session");
    if (f.object.datatype)
      cloud->object[k] =
          detail::LabelField<std::int32_t>(ReadValue(p + f.object.offset, f.object.datatype), path, "point", n, "object");
  }
}

// The per-point times of the kept records (a raw sweep's `time` field, seconds).
void ReadTimes(const Records& rec, FieldAt ft, const std::vector<std::size_t>& kept, PointCloud* cloud) {
  const double unit = ft.datatype == kUint32 ? 1e-9 : 1.0;  // `t`: nanoseconds
  cloud->time.resize(kept.size());
  for (std::size_t k = 0; k < kept.size(); ++k) {
    const std::size_t n = kept[k];
    const std::uint8_t* p = rec.data + (n / rec.cols) * rec.row_step + (n % rec.cols) * rec.point_step;
    cloud->time[k] = float(unit * ReadValue(p + ft.offset, ft.datatype));
  }
}

// The points of `rec`: float fields without the per-value type switch, others through ReadValue;
// with their labels and times when the file has them; fills `stats` (may be null).
PointCloud ReadRecords(const Records& rec, FieldAt fx, FieldAt fy, FieldAt fz, FieldAt fi, const LabelFields& labels,
                       FieldAt ft, const std::string& path, CloudReadStats* stats) {
  PointCloud cloud;
  cloud.reserve(rec.rows * rec.cols);
  auto is_float = [](FieldAt f) { return f.datatype == 0 || f.datatype == kFloat32; };
  auto read_float = [](const std::uint8_t* p, std::uint8_t) {
    float v;
    std::memcpy(&v, p, 4);
    return v;
  };
  std::vector<std::size_t> kept;
  std::vector<std::size_t>* keep = labels.Any() || ft.datatype ? &kept : nullptr;
  const std::size_t dropped = is_float(fx) && is_float(fy) && is_float(fz) && is_float(fi)
                                  ? AppendPoints(rec, fx, fy, fz, fi, read_float, &cloud, keep)
                                  : AppendPoints(rec, fx, fy, fz, fi, ReadValue, &cloud, keep);
  if (labels.Any()) ReadLabels(rec, labels, kept, path, &cloud);
  if (ft.datatype) ReadTimes(rec, ft, kept, &cloud);
  if (stats) {
    stats->points_in_file = rec.rows * rec.cols;
    stats->non_finite_dropped = dropped;
  }
  return cloud;
}

// PCL datatype of a field's TYPE and SIZE (both checked by CheckFields); 0 when PCL has none.
std::uint8_t Datatype(char type, long long size) {
  switch (type) {
    case 'F': return size == 4 ? kFloat32 : kFloat64;
    case 'I': return size == 1 ? kInt8 : size == 2 ? kInt16
                     : size == 4 ? kInt32 : 0;
    case 'U': return size == 1 ? kUint8 : size == 2 ? kUint16
                     : size == 4 ? kUint32 : 0;
    default: return 0;
  }
}

// The label fields as ltmapper's labelled PCDs write them (map/output.cpp): class U1, session
// U2, object I4. A field of that name with another type is some other tool's and is not read.
constexpr std::uint8_t kLabelTypes[3] = {kUint8, kUint16,
                                         kInt32};
FieldAt LabelAt(FieldAt f, int label) { return f.datatype == kLabelTypes[label] ? f : FieldAt{}; }

// A raw sweep's per-point time after the scan's timestamp: `time` in seconds (float, as Velodyne /
// LIO-SAM drivers write it; another type is an error naming the file) or `t` in nanoseconds
// (uint32, as Ouster's driver writes it; a `t` of another type is some other tool's, not read).
FieldAt TimeAt(const std::string& path, const std::string& name, FieldAt f) {
  if (!f.datatype) return f;
  if (name == "t") return f.datatype == kUint32 ? f : FieldAt{};
  if (f.datatype != kFloat32 && f.datatype != kFloat64)
    throw Error(path + ": PCD field 'time' must be F4 or F8 (seconds after the scan's timestamp)");
  return f;
}

// Field `name` at `f` as the scan's time field when it is one (TimeAt); `*time` holds the one
// found so far: a file with both `time` and `t` is an error naming it.
bool TakeTime(const std::string& path, const std::string& name, FieldAt f, FieldAt* time) {
  if (name != "time" && name != "t") return false;
  const FieldAt t = TimeAt(path, name, f);
  if (!t.datatype) return true;
  if (time->datatype) throw Error(path + ": PCD has both 'time' and 't' fields");
  *time = t;
  return true;
}

// x y z (intensity, and the labels) of a PCD: their offsets and datatypes in the point record, as
// binary data holds it and as the ascii and compressed data are put back (a field with COUNT > 1:
// its first value, as PCL reads it). Checked here, before any data is read: fuzz/fuzz_pcd found
// 212-byte files (an 8-byte float x, or no z at all) that made PCL's reader, which read such files
// once, ask for ~100 TB. Throws ltm::Error for no x y z or 8-byte integers among x y z intensity.
std::array<FieldAt, 8> BinaryFields(const std::string& path, const PcdHeader& h) {
  std::array<FieldAt, 8> at{};
  const char* names[9] = {"x", "y", "z", "intensity", "class", "session", "object", "time", "t"};
  std::size_t offset = 0;
  for (std::size_t i = 0; i < h.fields.size(); ++i) {
    for (int k = 0; k < 9; ++k) {
      if (h.fields[i] != names[k]) continue;
      const std::uint8_t type = Datatype(h.types[i], h.sizes[i]);
      if (TakeTime(path, names[k], {offset, type}, &at[7])) continue;
      if (k >= 4) {
        at[std::size_t(k)] = LabelAt({offset, type}, k - 4);
        continue;
      }
      if (!type)
        throw Error(path + ": PCD field '" + h.fields[i] + "' has an unsupported type (" +
                    std::string(1, h.types[i]) + std::to_string(h.sizes[i]) + ")");
      at[std::size_t(k)] = {offset, type};
    }
    offset += std::size_t(h.sizes[i]) * std::size_t(h.counts[i]);
  }
  if (!at[0].datatype || !at[1].datatype || !at[2].datatype) throw Error(path + ": PCD has no x y z fields");
  return at;
}

}  // namespace

Pose ReadPcdViewpoint(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open");
  const PcdHeader h = ParseHeader(path, in);
  Pose T = Pose::Identity();
  if (h.viewpoint.empty()) return T;
  const Eigen::Quaterniond q(h.viewpoint[3], h.viewpoint[4], h.viewpoint[5], h.viewpoint[6]);
  if (!(q.norm() > 1e-9) || !std::isfinite(q.norm()))
    throw Error(path + ": VIEWPOINT quaternion is zero or not finite");
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(h.viewpoint[0], h.viewpoint[1], h.viewpoint[2]);
  if (!T.translation().allFinite()) throw Error(path + ": VIEWPOINT translation is not finite");
  return T;
}

namespace {
// `count` point records of the header's layout in `bytes` (binary data as stored, or ascii and
// compressed data put back into it), read through ReadRecords with the fields BinaryFields found.
PointCloud ReadPointRecords(const std::string& path, const std::vector<std::uint8_t>& bytes, std::size_t count,
                            const PcdHeader& h, const std::array<FieldAt, 8>& f, CloudReadStats* stats) {
  Records rec;
  rec.data = bytes.data();
  rec.rows = 1;
  rec.cols = count;
  rec.point_step = h.PointStep();
  rec.row_step = rec.cols * rec.point_step;
  return ReadRecords(rec, f[0], f[1], f[2], f[3], {f[4], f[5], f[6]}, f[7], path, stats);
}

// An uncompressed binary PCD, its header parsed and its size checked: the records read here in
// one block (bench/bench_io: 0.4 ms for a 64 x 1024 scan, PCL's loadPCDFile 1.4-1.9 ms; going
// through PCL's reader and a per-value type switch took ~1.5-2 ms), never through PCL (see
// BinaryFields).
// The next `count` points of binary data from the stream's position (ReadPcd and PcdPieceReader).
PointCloud ReadBinaryPoints(const std::string& path, std::ifstream& in, const PcdHeader& h,
                            const std::array<FieldAt, 8>& f, std::size_t count, CloudReadStats* stats) {
  std::vector<std::uint8_t> bytes(count * h.PointStep());
  if (!in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size())))
    throw Error(path + ": cannot read the PCD data section");
  return ReadPointRecords(path, bytes, count, h, f, stats);
}


// The header of a PCD file opened in `in`, checked against the data's size and, when it has
// points, for x y z fields (fuzz/fuzz_pcd: a binary_compressed file without x made
// PCL's reader, which read such files once, dereference null).
PcdHeader OpenPcd(const std::string& path, std::ifstream& in, bool check_ascii_rows = true) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw Error(path + ": no such file");
  in.open(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open");
  PcdHeader h = ParseHeader(path, in);
  CheckDataSize(path, in, h, check_ascii_rows);
  if (h.points != 0)
    for (const char* name : {"x", "y", "z"})
      if (std::find(h.fields.begin(), h.fields.end(), name) == h.fields.end())
        throw Error(path + ": PCD has no x y z fields (no '" + name + "')");
  return h;
}

// One ascii value of a field of datatype `type` (one that Datatype gives) stored in `out` (its
// size); false when the token is no number of that kind.
bool StoreAscii(const std::string& token, std::uint8_t type, std::uint8_t* out) {
  const char* b = token.c_str();
  char* e = nullptr;
  auto put = [&](auto v) { std::memcpy(out, &v, sizeof(v)); };
  switch (type) {
    case kFloat32: put(std::strtof(b, &e)); break;
    case kFloat64: put(std::strtod(b, &e)); break;
    case kInt8: put(std::int8_t(std::strtoll(b, &e, 10))); break;
    case kInt16: put(std::int16_t(std::strtoll(b, &e, 10))); break;
    case kInt32: put(std::int32_t(std::strtoll(b, &e, 10))); break;
    case kUint8: put(std::uint8_t(std::strtoull(b, &e, 10))); break;
    case kUint16: put(std::uint16_t(std::strtoull(b, &e, 10))); break;
    case kUint32: put(std::uint32_t(std::strtoull(b, &e, 10))); break;
    default: return false;
  }
  return e != b && *e == '\0';
}

// An ascii PCD's rows as binary records (every field at its offset, in its type), so that
// ReadRecords reads all three formats alike; rows and values checked as they are read.
std::vector<std::uint8_t> AsciiRecords(const std::string& path, std::ifstream& in, const PcdHeader& h) {
  const std::size_t step = h.PointStep();
  std::vector<std::uint8_t> rec(std::size_t(h.points) * step, 0);
  std::size_t row = 0;
  ForEachAsciiRow(path, in, h, [&](std::size_t lineno, std::istringstream& values) {
    std::uint8_t* out = &rec[row++ * step];
    std::string t;
    for (std::size_t f = 0; f < h.fields.size(); ++f) {
      const std::uint8_t type = Datatype(h.types[f], h.sizes[f]);
      for (long long c = 0; c < h.counts[f]; ++c, out += h.sizes[f]) {
        values >> t;  // ForEachAsciiRow counted them
        if (type != 0 && !StoreAscii(t, type, out))
          throw Error(path, lineno, "PCD ascii value '" + t + "' of field '" + h.fields[f] + "' is no number of its TYPE");
      }
    }
  });
  return rec;
}

// A binary_compressed PCD's data as binary records: its LZF block (sizes checked by
// CheckDataSize) decompressed, then each field's column (the format stores field after field)
// put back into the points' records.
std::vector<std::uint8_t> CompressedRecords(const std::string& path, std::ifstream& in, const PcdHeader& h) {
  SeekData(in, h);
  std::uint32_t sizes[2] = {0, 0};  // compressed, uncompressed byte counts
  std::vector<char> packed;
  if (in.read(reinterpret_cast<char*>(sizes), 8)) {
    packed.resize(sizes[0]);
    in.read(packed.data(), std::streamsize(packed.size()));
  }
  if (!in) throw Error(path + ": cannot read the PCD's compressed block");
  std::vector<std::uint8_t> columns(sizes[1]);
  if (lzf_decompress(packed.data(), sizes[0], columns.data(), sizes[1]) != sizes[1])
    throw Error(path + ": corrupt PCD: the compressed block does not decompress to " + std::to_string(sizes[1]) + " bytes");
  const std::size_t n = std::size_t(h.points), step = h.PointStep();
  std::vector<std::uint8_t> rec(n * step);
  std::size_t offset = 0;  // the field's offset in a record; n * offset is its column's start
  for (std::size_t f = 0; f < h.fields.size(); ++f) {
    const std::size_t bytes = std::size_t(h.sizes[f]) * std::size_t(h.counts[f]);
    const std::uint8_t* column = &columns[n * offset];
    for (std::size_t i = 0; i < n; ++i) std::memcpy(&rec[i * step + offset], column + i * bytes, bytes);
    offset += bytes;
  }
  return rec;
}

// An ascii or binary_compressed PCD, read through the binary records' path.
PointCloud ReadTextOrCompressedPcd(const std::string& path, std::ifstream& in, const PcdHeader& h, CloudReadStats* stats) {
  const std::array<FieldAt, 8> f = BinaryFields(path, h);
  const std::vector<std::uint8_t> bytes = h.data == "ascii" ? AsciiRecords(path, in, h) : CompressedRecords(path, in, h);
  return ReadPointRecords(path, bytes, std::size_t(h.points), h, f, stats);
}

}  // namespace

PointCloud ReadPcd(const std::string& path, CloudReadStats* stats) {
  std::ifstream in;
  const PcdHeader h = OpenPcd(path, in, false);  // ascii rows: checked once, as they are read
  if (h.points == 0) {  // a valid empty scan; PCL would only print a warning
    if (stats) *stats = CloudReadStats{};
    return PointCloud{};
  }
  if (h.data == "binary") {
    SeekData(in, h);
    return ReadBinaryPoints(path, in, h, BinaryFields(path, h), std::size_t(h.points), stats);
  }
  return ReadTextOrCompressedPcd(path, in, h, stats);
}

std::size_t ReadPcdPointCount(const std::string& path) {
  std::ifstream in;
  return std::size_t(OpenPcd(path, in).points);
}

struct PcdPieceReader::Impl {
  std::string path;
  std::ifstream in;
  PcdHeader h;
  std::array<FieldAt, 8> fields;
  std::size_t left = 0;
};

PcdPieceReader::PcdPieceReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = path;
  m.h = OpenPcd(path, m.in);
  if (m.h.points == 0) return;
  if (m.h.data != "binary") throw Error(path + ": DATA " + m.h.data + " cannot be read a piece at a time (only binary)");
  m.fields = BinaryFields(path, m.h);
  m.left = std::size_t(m.h.points);
  SeekData(m.in, m.h);
}

PcdPieceReader::~PcdPieceReader() = default;
PcdPieceReader::PcdPieceReader(PcdPieceReader&&) noexcept = default;

bool PcdPieceReader::Next(std::size_t max_points, PointCloud* out) {
  Impl& m = *impl_;
  *out = PointCloud{};
  if (m.left == 0) return false;
  const std::size_t n = std::min(m.left, std::max<std::size_t>(max_points, 1));
  *out = ReadBinaryPoints(m.path, m.in, m.h, m.fields, n, nullptr);
  m.left -= n;
  return true;
}

namespace {
// The header PCL's PCDWriter writes for x y z intensity floats (the same bytes: test_io_formats); with `time`, a
// raw sweep's fifth float.
void WritePcdHeader(std::ostream& out, std::size_t points, const char* data, bool time = false) {
  out << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity" << (time ? " time" : "")
      << "\nSIZE 4 4 4 4" << (time ? " 4" : "") << "\nTYPE F F F F" << (time ? " F" : "") << "\nCOUNT 1 1 1 1"
      << (time ? " 1" : "") << "\nWIDTH " << points << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << points
      << "\nDATA " << data << "\n";
}

}  // namespace

void WritePcdPieces(const std::string& path, std::size_t points,
                    const std::function<void(const std::function<void(const PointCloud&)>& write)>& pieces) {
  // Streamed from the clouds' own arrays (x y z intensity, 16 bytes a point, as the format
  // stores them on this little-endian machine): no copy of the cloud, unlike PCL's writer (a
  // 32-byte-per-point PCL cloud plus the mapped file), so writing a session map costs no memory.
  static_assert(sizeof(PointXYZI) == 16, "PointXYZI must be four packed floats");
  static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "binary PCD data is little-endian");
  WriteFileAtomic(path, [&](std::ostream& out) {
    WritePcdHeader(out, points, "binary");
    std::size_t written = 0;
    pieces([&](const PointCloud& cloud) {
      out.write(reinterpret_cast<const char*>(cloud.points.data()), std::streamsize(cloud.size() * sizeof(PointXYZI)));
      written += cloud.size();
    });
    if (written != points)
      throw Error(path + ": " + std::to_string(written) + " points written, the header says " + std::to_string(points));
  });
}

namespace {
// A raw sweep: binary x y z intensity time (float32 each, 20 bytes a point).
void WriteTimedPcd(const std::string& path, const PointCloud& cloud) {
  cloud.CheckConsistent(path);
  WriteFileAtomic(path, [&](std::ostream& out) {
    WritePcdHeader(out, cloud.size(), "binary", true);
    std::vector<float> rec;
    rec.reserve(5 * cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const PointXYZI& p = cloud.points[i];
      rec.insert(rec.end(), {p.x, p.y, p.z, p.intensity, cloud.time[i]});
    }
    out.write(reinterpret_cast<const char*>(rec.data()), std::streamsize(rec.size() * sizeof(float)));
  });
}
}  // namespace

namespace {
// DATA ascii: x y z intensity a row, 9 significant digits (as PCL's writer, precision 9).
void WriteAsciiPoints(std::ostream& out, const PointCloud& cloud) {
  WritePcdHeader(out, cloud.size(), "ascii");
  char buf[128];
  for (const PointXYZI& p : cloud.points) {
    const int n = std::snprintf(buf, sizeof(buf), "%.9g %.9g %.9g %.9g\n", double(p.x), double(p.y), double(p.z),
                                double(p.intensity));
    out.write(buf, n);
  }
}

// DATA binary_compressed: the x, y, z and intensity columns one after another, LZF-compressed,
// after the compressed and the uncompressed byte counts (uint32 each).
void WriteCompressedPoints(const std::string& path, std::ostream& out, const PointCloud& cloud) {
  const std::size_t n = cloud.size();
  // lzf.h: the output may need 104 % of the input plus a few bytes; both sizes are stored as uint32.
  auto packed_size = [](std::size_t raw) { return raw + raw / 16 + 16; };
  if (packed_size(n * sizeof(PointXYZI)) > std::numeric_limits<std::uint32_t>::max())
    throw Error(path + ": " + std::to_string(n) + " points are too many for one binary_compressed PCD");
  std::vector<float> columns(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const PointXYZI& p = cloud.points[i];
    columns[i] = p.x, columns[n + i] = p.y, columns[2 * n + i] = p.z, columns[3 * n + i] = p.intensity;
  }
  const auto raw = std::uint32_t(columns.size() * sizeof(float));
  std::vector<char> packed(packed_size(raw));
  const std::uint32_t sizes[2] = {lzf_compress(columns.data(), raw, packed.data(), unsigned(packed.size())), raw};
  if (sizes[0] == 0) throw Error(path + ": LZF could not compress the points");
  WritePcdHeader(out, n, "binary_compressed");
  out.write(reinterpret_cast<const char*>(sizes), sizeof(sizes));
  out.write(packed.data(), std::streamsize(sizes[0]));
}
}  // namespace

void WritePcd(const std::string& path, const PointCloud& cloud, PcdFormat format) {
  if (!cloud.time.empty()) {
    if (format != PcdFormat::kBinary) throw Error(path + ": a cloud with per-point times is written as binary PCD only");
    WriteTimedPcd(path, cloud);
    return;
  }
  if (format == PcdFormat::kBinary) {
    WritePcdPieces(path, cloud.size(), [&](const auto& write) { write(cloud); });
    return;
  }
  WriteFileAtomic(path, [&](std::ostream& out) {
    if (cloud.empty()) {  // a valid PCD (POINTS 0); PCL's writers refused it
      WritePcdHeader(out, 0, format == PcdFormat::kAscii ? "ascii" : "binary");
      return;
    }
    if (format == PcdFormat::kAscii) WriteAsciiPoints(out, cloud);
    else WriteCompressedPoints(path, out, cloud);
  });
}

}  // namespace ltm::io
