// Internal helpers shared by the slam .cpp files (not part of the public API).
#pragma once

#include "ltmapper/slam/slam.hpp"

#include <chrono>
#include <string>
#include <vector>

namespace ltm::slam {

// Throws ltm::Error for sessions without keyframes, edges to missing keyframes, non-finite poses.
void ValidateSessionGraphs(const std::vector<Session>& sessions);
// Information of an inter-session loop from its registration fitness (paper: adaptive covariance).
Matrix6d LoopInformation(double fitness, const SlamConfig& cfg);

class Stopwatch {
 public:
  Stopwatch() : t0_(std::chrono::steady_clock::now()) {}
  double Seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  }

 private:
  std::chrono::steady_clock::time_point t0_;
};

}  // namespace ltm::slam
