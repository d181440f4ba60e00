// g2o pose graphs: VERTEX_SE3:QUAT id x y z qx qy qz qw and
// EDGE_SE3:QUAT a b x y z qx qy qz qw [21 values: upper triangle of the 6x6 information, row-major,
// order x y z rx ry rz]. SC-LIO-SAM writes 6 decimals and no information values.
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/formats.hpp"
#include "detail.hpp"

#include <fstream>
#include <map>
#include <sstream>
#include <unordered_map>

namespace ltm::io {

G2oGraph ReadG2o(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open (no such file or not readable)");
  G2oGraph g;
  std::unordered_map<int, std::size_t> vertex_line;
  std::vector<std::size_t> edge_lines;
  std::string line;
  std::size_t lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    std::istringstream ss(line);
    std::string tag;
    if (!(ss >> tag) || tag[0] == '#') continue;
    std::string rest;
    std::getline(ss, rest);
    if (tag == "VERTEX_SE3:QUAT") {
      const auto v = detail::ParseNumbers(rest, path, lineno);
      if (v.size() != 8)
        throw Error(path, lineno, "VERTEX_SE3:QUAT needs 8 numbers (id x y z qx qy qz qw), found " +
                                      std::to_string(v.size()));
      const int id = detail::IntegerId(v[0], "vertex id", path, lineno);
      if (vertex_line.count(id))
        throw Error(path, lineno, "duplicate vertex id " + std::to_string(id) + " (first on line " +
                                      std::to_string(vertex_line[id]) + ")");
      vertex_line[id] = lineno;
      g.vertices.emplace_back(id, detail::PoseFromQuat({v[1], v[2], v[3]}, v[4], v[5], v[6], v[7], path, lineno));
    } else if (tag == "EDGE_SE3:QUAT") {
      const auto v = detail::ParseNumbers(rest, path, lineno);
      if (v.size() != 9 && v.size() != 30)
        throw Error(path, lineno, "EDGE_SE3:QUAT needs 9 numbers (a b x y z qx qy qz qw) plus "
                                  "optionally 21 information values, found " + std::to_string(v.size()));
      Edge e;
      e.from = detail::IntegerId(v[0], "edge id", path, lineno);
      e.to = detail::IntegerId(v[1], "edge id", path, lineno);
      e.T_from_to = detail::PoseFromQuat({v[2], v[3], v[4]}, v[5], v[6], v[7], v[8], path, lineno);
      if (v.size() == 30) {
        std::size_t k = 9;
        for (int r = 0; r < 6; ++r)
          for (int c = r; c < 6; ++c) {
            e.information(r, c) = e.information(c, r) = v[k++];
          }
        if (!e.information.allFinite()) throw Error(path, lineno, "information matrix is not finite");
        e.has_information = true;
      }
      g.edges.push_back(e);
      edge_lines.push_back(lineno);
    } else if (tag == "FIX") {
      continue;  // gauge fixing is the optimiser's business, not the file's
    } else {
      throw Error(path, lineno, "unknown g2o tag '" + tag +
                                    "' (expected VERTEX_SE3:QUAT, EDGE_SE3:QUAT or FIX)");
    }
  }
  for (std::size_t i = 0; i < g.edges.size(); ++i) {
    for (int id : {g.edges[i].from, g.edges[i].to})
      if (!vertex_line.count(id))
        throw Error(path, edge_lines[i], "edge refers to missing vertex " + std::to_string(id));
  }
  return g;
}

void WriteG2o(const std::string& path, const G2oGraph& graph) {
  auto pose_text = [](const Pose& T) {
    const Eigen::Quaterniond q(T.rotation());
    const Eigen::Vector3d t = T.translation();
    std::string s;
    for (double v : {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()}) s += " " + detail::FormatDouble(v);
    return s;
  };
  WriteFileAtomic(path, [&](std::ostream& out) {
    for (const auto& [id, T] : graph.vertices) out << "VERTEX_SE3:QUAT " << id << pose_text(T) << "\n";
    for (const auto& e : graph.edges) {
      out << "EDGE_SE3:QUAT " << e.from << " " << e.to << pose_text(e.T_from_to);
      if (e.has_information)
        for (int r = 0; r < 6; ++r)
          for (int c = r; c < 6; ++c) out << " " << detail::FormatDouble(e.information(r, c));
      out << "\n";
    }
  });
}

}  // namespace ltm::io
