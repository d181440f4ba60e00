// Atomic file writes: write a temporary file in the destination directory, then rename it over
// the destination (rename within one file system is atomic on POSIX), so readers never see a
// partial file and a crash or an exception leaves the previous file (or none) in place.
#include "ltmapper/io/files.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

namespace fs = std::filesystem;

namespace ltm::io {
namespace {

std::string TempName(const std::string& path) {
  static std::atomic<unsigned long> counter{0};
  return path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

void EnsureParent(const std::string& path) {
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) MakeDirs(parent.string());
}

void RemoveQuietly(const std::string& path) {
  std::error_code ec;
  fs::remove(path, ec);
}

void Commit(const std::string& tmp, const std::string& path) {
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    RemoveQuietly(tmp);
    throw Error(path + ": cannot rename temporary file into place: " + ec.message());
  }
}

}  // namespace

std::string ReadFileText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path, 0, "cannot open (missing?)");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void MakeDirs(const std::string& dir) {
  if (dir.empty()) return;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) {
    throw Error(dir + ": cannot create directory" + (ec ? ": " + ec.message() : std::string()));
  }
}

void MakeWritableDir(const std::string& dir) {
  MakeDirs(dir);
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    throw Error(dir + ": output directory is not writable: " + std::strerror(errno));
}

void WriteFileAtomic(const std::string& path, const std::function<void(std::ostream&)>& write) {
  EnsureParent(path);
  const std::string tmp = TempName(path);
  try {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path + ": cannot open temporary file " + tmp + " for writing");
    write(out);
    out.flush();
    if (!out) throw Error(path + ": write failed (disk full or I/O error)");
    out.close();
    if (out.fail()) throw Error(path + ": closing the file failed");
  } catch (...) {
    RemoveQuietly(tmp);
    throw;
  }
  Commit(tmp, path);
}

void WritePathAtomic(const std::string& path, const std::function<void(const std::string&)>& write) {
  EnsureParent(path);
  const std::string tmp = TempName(path);
  try {
    write(tmp);
    if (!fs::is_regular_file(tmp)) throw Error(path + ": the writer did not create " + tmp);
  } catch (...) {
    RemoveQuietly(tmp);
    throw;
  }
  Commit(tmp, path);
}

}  // namespace ltm::io
