// Indexed file listing: scan files are named by an integer index ("000123.pcd" = 123) and
// sorted by that value, so "2.pcd" comes before "10.pcd" whatever the zero padding.
#include "ltmapper/io/files.hpp"

#include <algorithm>
#include <cctype>
#include <climits>
#include <filesystem>

namespace fs = std::filesystem;

namespace ltm::io {

int FileIndex(const std::string& filename) {
  const std::string stem = fs::path(filename).stem().string();
  if (stem.empty() || stem.size() > 9 ||
      !std::all_of(stem.begin(), stem.end(), [](unsigned char c) { return std::isdigit(c); })) {
    throw Error(filename + ": file name is not an integer index (expected e.g. 000123" +
                fs::path(filename).extension().string() + ")");
  }
  return std::stoi(stem);
}

std::vector<std::string> ListIndexedFiles(const std::string& dir, const std::string& ext) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(dir + ": no such directory");
  std::vector<std::pair<int, std::string>> found;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file()) continue;
    if (entry.path().extension().string() != ext) continue;
    found.emplace_back(FileIndex(entry.path().string()), entry.path().string());
  }
  if (ec) throw Error(dir + ": cannot list directory: " + ec.message());
  std::sort(found.begin(), found.end());
  for (std::size_t i = 1; i < found.size(); ++i) {
    if (found[i].first == found[i - 1].first) {
      throw Error(dir + ": duplicate index " + std::to_string(found[i].first) + ": " +
                  fs::path(found[i - 1].second).filename().string() + " and " +
                  fs::path(found[i].second).filename().string());
    }
  }
  std::vector<std::string> out;
  out.reserve(found.size());
  for (auto& f : found) out.push_back(std::move(f.second));
  return out;
}

}  // namespace ltm::io
