// Helpers shared by the test executables (header-only, tests only).
#pragma once

#include "ltmapper/core/core.hpp"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <random>
#include <sstream>
#include <string>

namespace ltm::test {

// Folder of the real LiDAR scans (../shared/data): $LTM_REAL_DATA, else ../shared/data next to
// the source tree when it exists, else "" (tests that need it skip with a message).
inline std::string RealDataDir() {
  if (const char* env = std::getenv("LTM_REAL_DATA"); env && *env) {
    return std::filesystem::exists(env) ? std::string(env) : std::string();
  }
  const std::filesystem::path guess = std::filesystem::path(LTM_SOURCE_DIR) / ".." / "shared" / "data";
  return std::filesystem::exists(guess) ? std::filesystem::canonical(guess).string() : std::string();
}

#define LTM_REQUIRE_REAL_DATA(dir_var)                                                  \
  const std::string dir_var = ::ltm::test::RealDataDir();                              \
  if (dir_var.empty()) GTEST_SKIP() << "real data not found: set LTM_REAL_DATA=../shared/data"

// Runs `f` and expects an ltm::Error whose message contains every string in `parts` (a file
// name, a line number, the key ...).
template <class F>
void ExpectError(F&& f, std::initializer_list<std::string> parts) {
  try {
    f();
    ADD_FAILURE() << "expected ltm::Error";
  } catch (const ltm::Error& e) {
    for (const auto& p : parts)
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << "'" << p << "' not in: " << e.what();
  }
}

// Expects every string of `parts` in `text` (one failure per missing part, showing the text).
inline void ExpectContains(const std::string& text, std::initializer_list<std::string> parts) {
  for (const auto& p : parts) EXPECT_NE(text.find(p), std::string::npos) << "'" << p << "' not in: " << text;
}

// A fresh temporary directory removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() /
            ("ltm_test_" + std::to_string(rd()) + "_" + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  std::string str() const { return path_.string(); }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

inline void WriteText(const std::string& path, const std::string& text) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

inline std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Runs the ltmapper executable with `args`; returns the exit code, stdout+stderr in *output.
inline int RunCli(const std::string& args, std::string* output = nullptr) {
  // Unique per process and call: ctest runs test executables in parallel.
  static int calls = 0;
  const std::string out_file = (std::filesystem::temp_directory_path() /
                                ("ltm_cli_" + std::to_string(::getpid()) + "_" + std::to_string(++calls)))
                                   .string();
  const std::string cmd = std::string(LTM_EXE) + " " + args + " > " + out_file + " 2>&1";
  const int status = std::system(cmd.c_str());
  if (output) *output = ReadText(out_file);
  std::filesystem::remove(out_file);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace ltm::test
