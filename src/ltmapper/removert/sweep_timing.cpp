// When the columns of deskewed scans fired (SweepTiming), estimated from the beams.
//
// A deskewed scan's returns were moved from the frame their column fired from into the frame of
// the timestamp, so a near return no longer lies at its beam's elevation: the sensor travelled
// between the two moments. Put back with the right timing, every return lies on its beam again.
// The estimate is the timing whose re-skewed elevations pile up most tightly: the sum of squared
// counts of a fine elevation histogram, largest when the returns fall on few, narrow peaks. It is
// searched over the turn's direction, the first column's azimuth, the period and the timestamp's
// place in the sweep, on a coarse grid (each return's elevation moved at its rate, linear in the
// firing moment) and then finer around the best (each return re-skewed). The caller keeps the
// result only when the scans re-skewed with it (io::Reskew) make more beams tell their returns.
#include "ltmapper/removert/detail.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace ltm::removert::detail {
namespace {

constexpr double kTwoPi = 6.283185307179586;
constexpr double kRadToDeg = 57.29577951308232;
// Elevation histogram bin [deg]: well below the beam spacing of any ring sensor (0.1 deg or more)
// and near the elevation precision of one return.
constexpr double kBinDeg = 0.02;
// The periods searched [s]: spinning LiDARs turn at 5 - 20 Hz; the range leaves margin on both sides.
constexpr double kMinPeriodS = 0.02, kMaxPeriodS = 0.3;
// The returns the search reads: enough for every beam's peak, few enough for thousands of
// candidates (the coarse grid reads a share of them).
constexpr std::size_t kMaxSamples = 10000, kCoarseSamples = 8000;

// One return: where it is deskewed, and its velocity in the timestamp's frame (it was at
// q - t u when its column fired t after the stamp: the motion's v + w x q); its elevation [deg],
// the rate at which that moves with the firing moment [deg/s], and its azimuth [rad], deskewed.
struct Sample {
  Eigen::Vector3f q, u;
  float elevation, rate, azimuth;
};

float ElevationDeg(const Eigen::Vector3f& p) {
  return FastAtan2(p.z(), std::sqrt(p.x() * p.x() + p.y() * p.y())) * float(kRadToDeg);
}

// Every k-th of `all`, at most n.
std::vector<Sample> Spread(const std::vector<Sample>& all, std::size_t n) {
  if (all.size() <= n) return all;
  std::vector<Sample> out;
  const double stride = double(all.size()) / double(n);
  for (std::size_t k = 0; k < n; ++k) out.push_back(all[std::size_t(double(k) * stride)]);
  return out;
}

// The returns beyond min_range_m whose elevation a timing can move by a histogram bin at least.
std::vector<Sample> Samples(const std::vector<PointCloud>& scans, const std::vector<SweepMotion>& motions,
                            double min_range_m) {
  constexpr float kStepS = 1e-3f;  // [s] finite difference of the rate
  std::vector<Sample> all;
  for (std::size_t s = 0; s < scans.size(); ++s) {
    const Eigen::Vector3f v = motions[s].v_mps.cast<float>(), w = motions[s].w_radps.cast<float>();
    for (const PointXYZI& pt : scans[s].points) {
      const Eigen::Vector3f q = pt.xyz();
      if (!q.allFinite() || double(q.norm()) < min_range_m) continue;
      const Eigen::Vector3f u = v + w.cross(q);
      const float e = ElevationDeg(q), rate = (ElevationDeg(q - kStepS * u) - e) / kStepS;
      if (std::fabs(rate) * float(kMaxPeriodS) < float(kBinDeg)) continue;
      all.push_back({q, u, e, rate, FastAtan2(q.y(), q.x())});
    }
  }
  return all;
}

// The histogram's concentration for timings: the sum of squared counts over two grids half a
// bin apart (a peak split by a bin edge counts in the other). `exact`: each return re-skewed
// (its column found from its own firing frame, one fixed-point step); else its elevation moved
// at its rate (fast, for the coarse grid).
class Score {
 public:
  Score(std::vector<Sample> samples, bool exact) : samples_(std::move(samples)), exact_(exact), share_(samples_.size()) {
    float lo = 90.f, hi = -90.f;
    for (const Sample& s : samples_) {
      const float reach = std::fabs(s.rate) * float(kMaxPeriodS);
      lo = std::min(lo, s.elevation - reach), hi = std::max(hi, s.elevation + reach);
    }
    lo_ = lo - float(kBinDeg);
    counts_.assign(2 * (std::size_t(std::max(0.f, (hi - lo_) / float(kBinDeg))) + 3), 0);
  }
  // Sets the turn and first column's azimuth: each return's share of the sweep fired before it.
  void Turn(int turn, double start_rad) {
    timing_.turn = turn, timing_.start_rad = start_rad, timing_.period_s = 1.0, timing_.stamp_share = 0.0;
    for (std::size_t i = 0; i < samples_.size(); ++i) share_[i] = float(timing_.TimeAt(samples_[i].azimuth));
  }
  // The score for that turn with the period and the timestamp's share; as deskewed for period 0.
  double operator()(double period_s, double stamp_share) {
    std::fill(counts_.begin(), counts_.end(), 0);
    const std::size_t half = counts_.size() / 2;
    const float p = float(period_s), h = float(stamp_share), top = float(half - 1);
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const float x = (Elevation(i, p, h) - lo_) / float(kBinDeg);
      ++counts_[std::size_t(std::clamp(x, 0.f, top))];
      ++counts_[half + std::size_t(std::clamp(x + 0.5f, 0.f, top))];
    }
    double total = 0.0;
    for (const std::int64_t c : counts_) total += double(c * c);
    return total;
  }

 private:
  float Elevation(std::size_t i, float period, float share) const {
    const Sample& s = samples_[i];
    const float t = period * (share_[i] - share);
    if (!exact_) return s.elevation + s.rate * t;
    const Eigen::Vector3f fired = s.q - t * s.u;  // the column it fired in, as its own frame sees it
    const float u = float(timing_.turn) * (float(timing_.start_rad) - FastAtan2(fired.y(), fired.x())) / float(kTwoPi);
    return ElevationDeg(s.q - period * (u - std::floor(u) - share) * s.u);
  }

  std::vector<Sample> samples_;
  bool exact_;
  std::vector<float> share_;  // per sample, for the current turn
  SweepTiming timing_;        // the current turn and start
  float lo_ = 0.f;
  std::vector<std::int64_t> counts_;
};

// The best of the timings around `best` (start, period and share each within +- span at `steps`
// steps a side), both turns when `turns`.
SweepTiming Refine(Score& score, SweepTiming best, double* best_score, double start_span, double period_span,
                   double share_span, int steps, bool turns) {
  const SweepTiming centre = best;
  for (const int turn : turns ? std::vector<int>{1, -1} : std::vector<int>{centre.turn})
    for (int a = -steps; a <= steps; ++a) {
      SweepTiming t = centre;
      t.turn = turn;
      t.start_rad = std::remainder(centre.start_rad + start_span * a / steps, kTwoPi);
      score.Turn(t.turn, t.start_rad);
      for (int p = -steps; p <= steps; ++p)
        for (int h = -steps; h <= steps; ++h) {
          t.period_s = std::clamp(centre.period_s + period_span * p / steps, kMinPeriodS, kMaxPeriodS);
          t.stamp_share = std::clamp(centre.stamp_share + share_span * h / steps, 0.0, 1.0);
          const double s = score(t.period_s, t.stamp_share);
          if (s > *best_score) *best_score = s, best = t;
        }
    }
  return best;
}

}  // namespace

SweepTiming EstimateSweepTiming(const std::vector<PointCloud>& scans, const std::vector<SweepMotion>& motions,
                                double min_range_m) {
  const std::vector<Sample> samples = Samples(scans, motions, min_range_m);
  if (samples.empty()) return {};
  // Coarse: the whole space (start every 10 deg, period every 0.02 s, share every quarter).
  Score coarse(Spread(samples, kCoarseSamples), false);
  double best_score = coarse(0.0, 0.0);
  const double as_deskewed = best_score;
  constexpr double kStartStep = kTwoPi / 36.0, kPeriodStep = 0.02, kShareStep = 0.25;
  SweepTiming best;
  for (const int turn : {1, -1})
    for (int a = 0; a < 36; ++a) {
      const double start = a * kStartStep - kTwoPi / 2;
      coarse.Turn(turn, start);
      for (double p = kMinPeriodS; p <= kMaxPeriodS + 1e-9; p += kPeriodStep)
        for (double h = 0.0; h <= 1.0 + 1e-9; h += kShareStep) {
          const double s = coarse(p, h);
          if (s > best_score) best_score = s, best = SweepTiming{true, p, start, turn, h};
        }
    }
  if (!best.known || best_score <= as_deskewed) return {};
  // Finer around it, re-skewing each return: each level a third of the last one's steps, down to
  // about 0.1 deg, 0.3 ms and 0.003 of the sweep.
  Score fine(Spread(samples, kMaxSamples), true);
  fine.Turn(best.turn, best.start_rad);
  best_score = fine(best.period_s, best.stamp_share);
  double start = kStartStep, period = kPeriodStep, share = kShareStep;
  for (int level = 0; level < 5; ++level) {
    best = Refine(fine, best, &best_score, start, period, share, 3, level == 0);
    start /= 3, period /= 3, share /= 3;
  }
  return best;
}

}  // namespace ltm::removert::detail
