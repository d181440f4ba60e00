// Scan Context descriptors as SC-LIO-SAM saves them: `rows` lines of `cols` numbers.
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/formats.hpp"
#include "detail.hpp"

#include <fstream>

namespace ltm::io {

Eigen::MatrixXd ReadScd(const std::string& path, int rows, int cols) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open (no such file or not readable)");
  Eigen::MatrixXd desc(rows, cols);
  std::string line;
  std::size_t lineno = 0;
  int r = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const auto v = detail::ParseNumbers(line, path, lineno);
    if (r >= rows)
      throw Error(path, lineno, "Scan Context has more than " + std::to_string(rows) + " rows");
    if (int(v.size()) != cols)
      throw Error(path, lineno, "Scan Context row has " + std::to_string(v.size()) +
                                    " values, expected " + std::to_string(cols));
    for (int c = 0; c < cols; ++c) desc(r, c) = v[std::size_t(c)];
    ++r;
  }
  if (r != rows)
    throw Error(path, lineno, "Scan Context has " + std::to_string(r) + " rows, expected " +
                                  std::to_string(rows));
  return desc;
}

void WriteScd(const std::string& path, const Eigen::MatrixXd& desc) {
  WriteFileAtomic(path, [&](std::ostream& out) {
    for (int r = 0; r < desc.rows(); ++r) {
      for (int c = 0; c < desc.cols(); ++c)
        out << (c ? " " : "") << detail::FormatDouble(desc(r, c));
      out << "\n";
    }
  });
}

}  // namespace ltm::io
