// Shared by the libFuzzer harnesses: the input goes to a temp file when the reader takes a path;
// ltm::Error is the expected answer to bad input, anything else (another exception, a sanitizer
// report, an abort) is a finding.
#pragma once

#include "ltmapper/core/core.hpp"

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <unistd.h>

namespace ltm::fuzz {

// One file per process (and extension), rewritten for every input; in /dev/shm when available.
inline std::string WriteInput(const std::uint8_t* data, std::size_t size, const std::string& ext) {
  static const std::string dir = [] {
    if (const char* d = std::getenv("LTM_FUZZ_TMP")) return std::string(d);
    return std::string(access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp");
  }();
  const std::string path = dir + "/ltm_fuzz_" + std::to_string(getpid()) + ext;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

// Runs `f`; swallows ltm::Error only.
template <class F>
void Expect(F&& f) {
  try {
    f();
  } catch (const ltm::Error&) {
  }
}

}  // namespace ltm::fuzz
