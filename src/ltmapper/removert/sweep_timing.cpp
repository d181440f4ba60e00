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
// result only when the scans re-skewed with it (io::Reskew) make a larger share of their beams
// tell their returns.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/core/core.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace ltm::removert::detail {
namespace {

constexpr double kTwoPi = 360.0 * kRadPerDeg;
// Elevation histogram bin [deg]: well below the beam spacing of any ring sensor (0.1 deg or more)
// and near the elevation precision of one return.
constexpr double kBinDeg = 0.02;
// The periods searched [s]: spinning LiDARs turn at 5 - 20 Hz; the range leaves margin on both sides.
constexpr double kMinPeriodS = 0.02, kMaxPeriodS = 0.3;
// The returns the search reads: enough for every beam's peak, few enough for thousands of
// candidates (the coarse grid reads a share of them).
constexpr std::size_t kMaxSamples = 12000, kCoarseSamples = 8000;

// One return: where it is deskewed, and its velocity in the timestamp's frame (it was at
// q - t u when its column fired t after the stamp: the motion's v + w x q); its elevation [deg],
// the rate at which that moves with the firing moment [deg/s], and its azimuth [rad], deskewed.
struct Sample {
  Eigen::Vector3f q, u;
  float elevation, rate, azimuth;
};

float ElevationDeg(const Eigen::Vector3f& p) {
  return FastAtan2(p.z(), std::sqrt(p.x() * p.x() + p.y() * p.y())) / float(kRadPerDeg);
}

// Every k-th of `all`, at most n.
std::vector<Sample> Spread(const std::vector<Sample>& all, std::size_t n) {
  if (all.size() <= n) return all;
  std::vector<Sample> out;
  const double stride = double(all.size()) / double(n);
  for (std::size_t k = 0; k < n; ++k) out.push_back(all[std::size_t(double(k) * stride)]);
  return out;
}

// The returns beyond min_range_m. Those a timing hardly moves (far, or seen sideways) count too:
// they hold the beams' own elevations, which the moved ones must come back to (without them, a
// wrong timing that moves the near returns alike piles them up as tightly, off their beams).
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
      all.push_back({q, u, e, rate, FastAtan2(q.y(), q.x())});
    }
  }
  return all;
}

// For the seam: every return within `reach` of azimuth `seam` (the few that tell where the sweep
// begins and ends), and `n` of the others spread over the rest (the beams' elevations).
std::vector<Sample> AtTheSeam(const std::vector<Sample>& all, double seam, double reach, std::size_t n) {
  std::vector<Sample> near, rest;
  for (const Sample& s : all)
    (std::fabs(std::remainder(double(s.azimuth) - seam, kTwoPi)) <= reach ? near : rest).push_back(s);
  std::vector<Sample> out = Spread(rest, n);
  out.insert(out.end(), near.begin(), near.end());
  return out;
}

// The histogram's concentration for timings: the sum of squared counts over two grids half a
// bin apart (a peak split by a bin edge counts in the other). `exact`: each return re-skewed
// (its column found from its own firing frame, one fixed-point step); else its elevation moved
// at its rate (fast, for the coarse grid). One per worker: the samples are shared, read only.
class Score {
 public:
  // The histogram spans every elevation: a return re-skewed far off its linear reach (a near one,
  // at the seam) must not pile up in an edge bin.
  Score(const std::vector<Sample>& samples, bool exact)
      : samples_(samples), exact_(exact), share_(samples_.size()), counts_(2 * (std::size_t(180.0 / kBinDeg) + 2), 0) {}
  // Sets the turn and first column's azimuth: each return's share of the sweep fired before it.
  void Turn(int turn, double start_rad) {
    timing_.turn = turn, timing_.start_rad = start_rad;
    for (std::size_t i = 0; i < samples_.size(); ++i) share_[i] = float(timing_.ShareAt(samples_[i].azimuth));
  }
  // The score for that turn with the period and the timestamp's share; as deskewed for period 0.
  double operator()(double period_s, double stamp_share) {
    const std::size_t half = counts_.size() / 2;
    const float p = float(period_s), h = float(stamp_share), top = float(half - 1);
    std::size_t lo = half, hi = 0;  // the bins touched (of the first grid)
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      const float x = (Elevation(i, p, h) + 90.f) / float(kBinDeg);
      const auto b = std::size_t(std::clamp(x, 0.f, top)), b2 = std::size_t(std::clamp(x + 0.5f, 0.f, top));
      ++counts_[b];
      ++counts_[half + b2];
      lo = std::min(lo, b), hi = std::max(hi, b2);
    }
    double total = 0.0;
    for (std::size_t b = lo; b <= hi && lo <= hi; ++b) {  // summed and cleared for the next timing
      total += double(counts_[b] * counts_[b]) + double(counts_[half + b] * counts_[half + b]);
      counts_[b] = counts_[half + b] = 0;
    }
    return total;
  }

 private:
  float Elevation(std::size_t i, float period, float share) const {
    const Sample& s = samples_[i];
    const float t = period * (share_[i] - share);
    if (!exact_) return s.elevation + s.rate * t;
    const Eigen::Vector3f fired = s.q - t * s.u;  // the column it fired in, as its own frame sees it
    // SweepTiming::ShareAt of its azimuth there, in float (the search's hot loop).
    const float u = float(timing_.turn) * (float(timing_.start_rad) - FastAtan2(fired.y(), fired.x())) / float(kTwoPi);
    return ElevationDeg(s.q - period * (u - std::floor(u) - share) * s.u);
  }

  const std::vector<Sample>& samples_;
  bool exact_;
  std::vector<float> share_;  // per sample, for the current turn
  SweepTiming timing_;        // the current turn and start (ShareAt)
  std::vector<std::int64_t> counts_;
};

// The best timing of n starts (a turn and first column's azimuth each), start k tried by
// try_start(k, score, &best, &best_score) with a Score of its own on the `threads` workers. Kept
// in k order, ties to the first: the result of trying them all in one loop.
template <class TryStart>
void BestOfStarts(const std::vector<Sample>& samples, bool exact, std::size_t n, int threads,
                  const TryStart& try_start, SweepTiming* best, double* best_score) {
  std::vector<SweepTiming> bests(n, *best);
  std::vector<double> scores(n, *best_score);
  ParallelFor(n, threads, [&](std::size_t k) {
    Score score(samples, exact);
    try_start(k, score, &bests[k], &scores[k]);
  });
  for (std::size_t k = 0; k < n; ++k)
    if (scores[k] > *best_score) *best_score = scores[k], *best = bests[k];
}

// The score of `best` itself, on `samples`.
double ScoreOf(const std::vector<Sample>& samples, bool exact, const SweepTiming& best) {
  Score score(samples, exact);
  score.Turn(best.turn, best.start_rad);
  return score(best.period_s, best.stamp_share);
}

// The best of the timings around `best` (start, period and share each within +- span at `steps`
// steps a side; the turn as it is), on `samples` re-skewed.
SweepTiming Refine(const std::vector<Sample>& samples, SweepTiming best, double* best_score, double start_span,
                   double period_span, double share_span, int steps, int threads) {
  const SweepTiming centre = best;
  const auto try_start = [&](std::size_t k, Score& score, SweepTiming* out, double* out_score) {
    const int a = int(k) - steps;
    SweepTiming t = centre;
    t.start_rad = std::remainder(centre.start_rad + start_span * a / steps, kTwoPi);
    score.Turn(t.turn, t.start_rad);
    for (int p = -steps; p <= steps; ++p)
      for (int h = -steps; h <= steps; ++h) {
        t.period_s = std::clamp(centre.period_s + period_span * p / steps, kMinPeriodS, kMaxPeriodS);
        t.stamp_share = std::clamp(centre.stamp_share + share_span * h / steps, 0.0, 1.0);
        const double s = score(t.period_s, t.stamp_share);
        if (s > *out_score) *out_score = s, *out = t;
      }
  };
  BestOfStarts(samples, true, std::size_t(2 * steps + 1), threads, try_start, &best, best_score);
  return best;
}

// The first column's azimuth and the period trade off: a shorter sweep whose seam lies a little
// further on fires most columns at nearly the same moments, and only the returns at the seam tell
// them apart. Both on a fine grid together around `best`: the seam within +- kSeamSpanRad at
// kSeamStepRad, the period within +- kSeamPeriodSpan of it at kSeamPeriodStep.
constexpr double kSeamSpanRad = 5.0 * kTwoPi / 360.0, kSeamStepRad = 0.25 * kTwoPi / 360.0;
constexpr double kSeamPeriodSpan = 0.04, kSeamPeriodStep = 0.005;  // [-] of the period
SweepTiming AlongTheSeam(const std::vector<Sample>& samples, SweepTiming best, double* best_score, int threads) {
  const SweepTiming centre = best;
  const int seams = int(std::lround(kSeamSpanRad / kSeamStepRad));
  const int periods = int(std::lround(kSeamPeriodSpan / kSeamPeriodStep));
  const auto try_start = [&](std::size_t k, Score& score, SweepTiming* out, double* out_score) {
    SweepTiming t = centre;
    t.start_rad = std::remainder(centre.start_rad + (int(k) - seams) * kSeamStepRad, kTwoPi);
    score.Turn(t.turn, t.start_rad);
    for (int p = -periods; p <= periods; ++p) {
      t.period_s = std::clamp(centre.period_s * (1.0 + p * kSeamPeriodStep), kMinPeriodS, kMaxPeriodS);
      const double s = score(t.period_s, t.stamp_share);
      if (s > *out_score) *out_score = s, *out = t;
    }
  };
  BestOfStarts(samples, true, std::size_t(2 * seams + 1), threads, try_start, &best, best_score);
  return best;
}

// Coarse: the whole space (start every 10 deg, period every 0.02 s, share every quarter, both
// turns), each return's elevation moved at its rate. Unknown when nothing beats the scans as
// they are (*best_score: their score).
constexpr double kStartStep = kTwoPi / 36.0, kPeriodStep = 0.02, kShareStep = 0.25;
SweepTiming Coarse(const std::vector<Sample>& samples, int threads) {
  double best_score = ScoreOf(samples, false, SweepTiming{true, 0.0, 0.0, 1, 0.0});  // period 0: as deskewed
  const double as_deskewed = best_score;
  const auto try_start = [&](std::size_t k, Score& score, SweepTiming* out, double* out_score) {
    const int turn = k < 36 ? 1 : -1;
    const double start = double(k % 36) * kStartStep - kTwoPi / 2;
    score.Turn(turn, start);
    for (double p = kMinPeriodS; p <= kMaxPeriodS + 1e-9; p += kPeriodStep)
      for (double h = 0.0; h <= 1.0 + 1e-9; h += kShareStep) {
        const double s = score(p, h);
        if (s > *out_score) *out_score = s, *out = SweepTiming{true, p, start, turn, h};
      }
  };
  SweepTiming best;
  BestOfStarts(samples, false, 72, threads, try_start, &best, &best_score);
  return best.known && best_score > as_deskewed ? best : SweepTiming{};
}

}  // namespace

SweepTiming EstimateSweepTiming(const std::vector<PointCloud>& scans, const std::vector<SweepMotion>& motions,
                                double min_range_m, int threads) {
  const std::vector<Sample> samples = Samples(scans, motions, min_range_m);
  if (samples.empty()) return {};
  SweepTiming best = Coarse(Spread(samples, kCoarseSamples), threads);
  if (!best.known) return {};
  // Finer around it, re-skewing each return: the coarse neighbourhood at a third of its steps;
  // then the seam and the period together (AlongTheSeam) and the last digits, on every return near
  // the seam (AtTheSeam: on a sparse sensor a share of them leaves the seam degrees off).
  const std::vector<Sample> fine = Spread(samples, kMaxSamples);
  double best_score = ScoreOf(fine, true, best);
  best = Refine(fine, best, &best_score, kStartStep, kPeriodStep, kShareStep, 3, threads);
  const std::vector<Sample> seam = AtTheSeam(samples, best.start_rad, kSeamSpanRad + kStartStep / 3, kMaxSamples);
  best_score = ScoreOf(seam, true, best);
  best = AlongTheSeam(seam, best, &best_score, threads);
  double start = kSeamStepRad, period = kSeamPeriodStep * best.period_s, share = kShareStep / 3;
  for (int level = 0; level < 2; ++level) {
    best = Refine(seam, best, &best_score, start, period, share, 3, threads);
    start /= 3, period /= 3, share /= 3;
  }
  return best;
}

}  // namespace ltm::removert::detail
