// Voxel-grid downsampling by sorting (voxel key, point index) records.
//
// Why sorting rather than a hash map: the output must be ordered by voxel key anyway, and with
// the point index as tie-breaker the order inside a voxel is the input order, so centroid sums
// are formed in the same order whatever the thread count (bit-identical output).
// Common case: the occupied voxel indices span < 2^21 per axis and pack into one uint64 relative
// to the minimum index (16-byte records, fast sort). Otherwise (e.g. 1 cm voxels over +-1e6 m)
// a 3 x int64 key is used; both orders are lexicographic (x, y, z).
// A concatenation of voxelised clouds (VoxelDownsampleRuns) is reduced without records: its runs
// are already in key order, so a k-way merge per key range gives the same sums in the same order.
#include "ltmapper/geometry/geometry.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace ltm::geometry {

namespace {

constexpr int kPackBits = 21;                     // bits per axis in the packed key
constexpr std::int64_t kPackSpan = std::int64_t(1) << kPackBits;
constexpr double kMaxVoxelIndex = 4.0e18;         // |index| beyond this would overflow int64
constexpr std::size_t kGrain = 4096;              // points per TBB task
constexpr std::size_t kMergeRangePoints = 65536;  // points per parallel key range of a run merge
constexpr std::size_t kMaxMergeRanges = 256;      // at most this many key ranges

using Index3 = std::array<std::int64_t, 3>;

struct PackedRec {
  std::uint64_t key;
  std::uint32_t idx;
  bool operator<(const PackedRec& o) const { return key != o.key ? key < o.key : idx < o.idx; }
  bool SameVoxel(const PackedRec& o) const { return key == o.key; }
};

struct WideRec {
  Index3 key;
  std::uint32_t idx;
  bool operator<(const WideRec& o) const { return key != o.key ? key < o.key : idx < o.idx; }
  bool SameVoxel(const WideRec& o) const { return key == o.key; }
};

struct Bounds {
  Index3 lo{std::numeric_limits<std::int64_t>::max(), std::numeric_limits<std::int64_t>::max(),
            std::numeric_limits<std::int64_t>::max()};
  Index3 hi{std::numeric_limits<std::int64_t>::min(), std::numeric_limits<std::int64_t>::min(),
            std::numeric_limits<std::int64_t>::min()};
  std::size_t finite = 0;
  bool overflow = false;
  void Add(const Index3& k) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], k[a]);
      hi[a] = std::max(hi[a], k[a]);
    }
    ++finite;
  }
  void Join(const Bounds& o) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], o.lo[a]);
      hi[a] = std::max(hi[a], o.hi[a]);
    }
    finite += o.finite;
    overflow = overflow || o.overflow;
  }
};

inline bool Finite(const PointXYZI& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

// Voxel index of a finite point; false when an index would not fit in int64. floor() by
// truncation and a correction: the same integer without a libm call per coordinate (the hot
// part of voxelising a scan).
inline bool VoxelOf(const PointXYZI& p, double voxel_m, Index3* k) {
  const double v[3] = {double(p.x) / voxel_m, double(p.y) / voxel_m, double(p.z) / voxel_m};
  for (int a = 0; a < 3; ++a) {
    if (std::abs(v[a]) > kMaxVoxelIndex) return false;
    std::int64_t t = static_cast<std::int64_t>(v[a]);
    if (double(t) > v[a]) --t;
    (*k)[a] = t;
  }
  return true;
}

// LSD radix sort of packed records by key, `bits` wide (stable: records in index order stay in
// index order within a key, which is the (key, idx) order of PackedRec::operator<). One thread;
// faster than a comparison sort on a single scan.
void RadixSort(std::vector<PackedRec>& recs, int bits) {
  constexpr int kDigit = 11;
  std::vector<PackedRec> tmp(recs.size());
  std::vector<std::uint32_t> count(std::size_t(1) << kDigit);
  const std::uint64_t mask = (std::uint64_t(1) << kDigit) - 1;
  for (int shift = 0; shift < bits; shift += kDigit) {
    std::fill(count.begin(), count.end(), 0u);
    for (const PackedRec& r : recs) ++count[(r.key >> shift) & mask];
    std::uint32_t sum = 0;
    for (auto& c : count) sum += std::exchange(c, sum);
    for (const PackedRec& r : recs) tmp[count[(r.key >> shift) & mask]++] = r;
    recs.swap(tmp);
  }
}

// Centroid of a voxel's points, summed in double in the order they are added (the order fixes
// the result bit for bit).
struct VoxelSum {
  double x = 0, y = 0, z = 0, intensity = 0;
  std::size_t n = 0;
  void Add(const PointXYZI& p) {
    x += p.x;
    y += p.y;
    z += p.z;
    intensity += p.intensity;
    ++n;
  }
  PointXYZI Mean() const {
    const double inv = 1.0 / double(n);
    return {float(x * inv), float(y * inv), float(z * inv), float(intensity * inv)};
  }
};

// Sorted records -> one centroid per run of equal keys.
template <class Rec>
PointCloud Reduce(const PointCloud& cloud, const std::vector<Rec>& recs, int threads) {
  std::vector<std::size_t> starts;
  starts.reserve(recs.size() / 4 + 1);
  for (std::size_t i = 0; i < recs.size(); ++i)
    if (i == 0 || !recs[i].SameVoxel(recs[i - 1])) starts.push_back(i);
  starts.push_back(recs.size());
  const std::size_t m = starts.size() - 1;

  PointCloud out;
  out.points.resize(m);
  if (!cloud.cls.empty()) out.cls.resize(m);
  if (!cloud.session.empty()) out.session.resize(m);
  if (!cloud.object.empty()) out.object.resize(m);
  ParallelForChunks(m, threads, kGrain / 4, [&](std::size_t begin, std::size_t end) {
    for (std::size_t v = begin; v != end; ++v) {
      VoxelSum sum;
      for (std::size_t j = starts[v]; j < starts[v + 1]; ++j) sum.Add(cloud.points[recs[j].idx]);
      out.points[v] = sum.Mean();
      const std::uint32_t first = recs[starts[v]].idx;
      if (!cloud.cls.empty()) out.cls[v] = cloud.cls[first];
      if (!cloud.session.empty()) out.session[v] = cloud.session[first];
      if (!cloud.object.empty()) out.object[v] = cloud.object[first];
    }
  });
  return out;
}

// A run of the concatenation: points [b, e).
struct Span {
  std::size_t b, e;
};

// The non-empty runs, or none when a run's keys are out of order.
template <class KeyFn>
std::vector<Span> SortedSpans(const PointCloud& cloud, std::vector<std::size_t> runs, const KeyFn& key, int threads) {
  runs.push_back(cloud.size());
  std::vector<Span> spans;
  for (std::size_t r = 0; r + 1 < runs.size(); ++r)
    if (runs[r + 1] > runs[r]) spans.push_back({runs[r], runs[r + 1]});
  std::vector<char> sorted(spans.size(), 1);
  ParallelFor(spans.size(), threads, [&](std::size_t r) {
    std::uint64_t prev = key(cloud.points[spans[r].b]);
    for (std::size_t i = spans[r].b + 1; i < spans[r].e && sorted[r]; ++i) {
      const std::uint64_t k = key(cloud.points[i]);
      sorted[r] = k >= prev;
      prev = k;
    }
  });
  for (char ok : sorted)
    if (!ok) return {};
  return spans;
}

// Key ranges merged in parallel: split at evenly spaced keys of all runs together (strictly
// increasing), sampled from every run in proportion to its length, so that each range holds
// about as many points whatever the runs cover (split at the longest run's keys alone, the other
// runs' points outside its key span all fell in the first and last range: a map batch of 32
// scans merged on one or two cores, issue 18). A voxel's points lie in one range, so the output
// does not depend on the split. bound[r * (ranges + 1) + t] is the first point of run r in range
// t (key >= split[t - 1]); returns the number of ranges.
template <class KeyFn>
std::size_t MergeRanges(const PointCloud& cloud, const std::vector<Span>& spans, const KeyFn& key,
                        std::vector<std::size_t>* bound, int threads) {
  const std::size_t ranges = std::max<std::size_t>(1, std::min(kMaxMergeRanges, cloud.size() / kMergeRangePoints));
  constexpr std::size_t kSamplesPerRange = 8;
  std::vector<std::uint64_t> sample;
  for (const Span& sp : spans) {
    const std::size_t len = sp.e - sp.b;
    const std::size_t m = (ranges * kSamplesPerRange * len + cloud.size() - 1) / cloud.size();
    for (std::size_t j = 0; j < m; ++j) sample.push_back(key(cloud.points[sp.b + len * j / m]));
  }
  std::sort(sample.begin(), sample.end());
  std::vector<std::uint64_t> split;
  for (std::size_t t = 1; t < ranges && !sample.empty(); ++t) {
    const std::uint64_t k = sample[sample.size() * t / ranges];
    if (split.empty() || k > split.back()) split.push_back(k);
  }
  const std::size_t nr = split.size() + 1;
  bound->assign(spans.size() * (nr + 1), 0);
  ParallelFor(spans.size(), threads, [&](std::size_t r) {
    std::size_t* row = &(*bound)[r * (nr + 1)];
    row[0] = spans[r].b;
    row[nr] = spans[r].e;
    for (std::size_t t = 1; t < nr; ++t) {
      std::size_t lo = row[t - 1], hi = spans[r].e;
      while (lo < hi) {
        const std::size_t mid = lo + (hi - lo) / 2;
        if (key(cloud.points[mid]) < split[t - 1]) lo = mid + 1;
        else hi = mid;
      }
      row[t] = lo;
    }
  });
  return nr;
}

// K-way merge of the runs' points in key range t (of nr): one centroid per voxel, summed in run
// order, arrays from the voxel's first point.
template <class KeyFn>
PointCloud MergeRange(const PointCloud& cloud, std::size_t runs, const std::vector<std::size_t>& bound,
                      std::size_t nr, std::size_t t, const KeyFn& key) {
  struct Head {
    std::uint64_t key;
    std::uint32_t run;
    std::size_t i;
    bool operator>(const Head& o) const { return key != o.key ? key > o.key : run > o.run; }
  };
  std::vector<Head> heap;
  std::size_t total = 0;
  for (std::size_t r = 0; r < runs; ++r) {
    const std::size_t b = bound[r * (nr + 1) + t], e = bound[r * (nr + 1) + t + 1];
    total += e - b;
    if (b < e) heap.push_back({key(cloud.points[b]), std::uint32_t(r), b});
  }
  const auto later = std::greater<Head>();
  std::make_heap(heap.begin(), heap.end(), later);
  auto pop = [&]() {  // the smallest head; its run's next point takes its place
    std::pop_heap(heap.begin(), heap.end(), later);
    const Head h = heap.back();
    const std::size_t next = h.i + 1;
    if (next < bound[h.run * (nr + 1) + t + 1]) {
      heap.back() = {key(cloud.points[next]), h.run, next};
      std::push_heap(heap.begin(), heap.end(), later);
    } else {
      heap.pop_back();
    }
    return h;
  };
  PointCloud part;
  part.points.reserve(total);
  while (!heap.empty()) {
    const Head first = pop();
    VoxelSum sum;
    sum.Add(cloud.points[first.i]);
    while (!heap.empty() && heap.front().key == first.key) sum.Add(cloud.points[pop().i]);
    part.points.push_back(sum.Mean());
    if (!cloud.cls.empty()) part.cls.push_back(cloud.cls[first.i]);
    if (!cloud.session.empty()) part.session.push_back(cloud.session[first.i]);
    if (!cloud.object.empty()) part.object.push_back(cloud.object[first.i]);
  }
  return part;
}

// A concatenation of voxelised clouds (runs starting at `runs`, ascending, first 0), every
// point finite, keys from `key`: one centroid per voxel by a k-way merge of the runs, read
// straight from the points, with no record arrays (the record path holds two 16-byte records per
// input point). Key ranges, split at keys of the longest run, are merged in parallel. A voxel's
// points are summed in run order and its arrays come from its first point, as the record path
// does (std::merge keeps equal keys in run order), so the output is bit-identical to it.
// False, writing nothing, when a run is out of order.
template <class KeyFn>
bool ReduceRuns(const PointCloud& cloud, const std::vector<std::size_t>& runs, const KeyFn& key, PointCloud* out,
                int threads) {
  const std::vector<Span> spans = SortedSpans(cloud, runs, key, threads);
  if (spans.empty()) return false;
  std::vector<std::size_t> bound;
  const std::size_t nr = MergeRanges(cloud, spans, key, &bound, threads);
  std::vector<PointCloud> parts(nr);
  ParallelFor(nr, threads, [&](std::size_t t) { parts[t] = MergeRange(cloud, spans.size(), bound, nr, t, key); });
  *out = Concatenate(std::move(parts), threads);
  return true;
}

// The voxel index bounds of the cloud's finite points; throws when an index overflows.
Bounds VoxelBounds(const PointCloud& cloud, double voxel_m) {
  const Bounds b = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, cloud.size(), kGrain), Bounds{},
      [&](const tbb::blocked_range<std::size_t>& r, Bounds acc) {
        Index3 k{0, 0, 0};
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          const PointXYZI& p = cloud.points[i];
          if (!Finite(p)) continue;
          if (!VoxelOf(p, voxel_m, &k)) {
            acc.overflow = true;
            continue;
          }
          acc.Add(k);
        }
        return acc;
      },
      [](Bounds a, const Bounds& o) {
        a.Join(o);
        return a;
      });
  if (b.overflow)
    throw Error("VoxelDownsample: voxel index overflows int64 (voxel " + std::to_string(voxel_m) +
                " m too small for the coordinates)");
  return b;
}

// Sorted (key, index) records of the finite points -> centroids. `point_index(j)`: the j-th
// finite point; `fill(rec, i)` sets a record's key.
template <class Rec, class IndexFn, class FillFn>
std::vector<Rec> Records(std::size_t m, const IndexFn& point_index, const FillFn& fill, int threads) {
  std::vector<Rec> recs(m);
  ParallelForChunks(m, threads, kGrain, [&](std::size_t begin, std::size_t end) {
    for (std::size_t j = begin; j != end; ++j) fill(recs[j], point_index(j));
  });
  return recs;
}

// `runs` (may be null): the cloud is a concatenation of voxelised clouds starting there.
PointCloud Downsample(const PointCloud& cloud, double voxel_m, int threads, const std::vector<std::size_t>* runs) {
  const std::size_t n = cloud.size();
  const Bounds b = VoxelBounds(cloud, voxel_m);
  if (b.finite == 0) return PointCloud{};
  // Compact list of finite point indices, in input order.
  std::vector<std::uint32_t> finite_idx;
  const bool all_finite = b.finite == n;
  if (!all_finite) {
    finite_idx.reserve(b.finite);
    for (std::size_t i = 0; i < n; ++i)
      if (Finite(cloud.points[i])) finite_idx.push_back(std::uint32_t(i));
  }
  auto point_index = [&](std::size_t j) { return all_finite ? std::uint32_t(j) : finite_idx[j]; };
  bool packable = true;
  int width[3];  // bits of each axis' index span: keys as narrow as the cloud allows
  for (int a = 0; a < 3; ++a) {
    const std::int64_t span = b.hi[a] - b.lo[a];
    packable = packable && span < kPackSpan;
    width[a] = 0;
    while ((span >> width[a]) != 0) ++width[a];
  }
  if (!packable) {
    auto recs = Records<WideRec>(b.finite, point_index, [&](WideRec& rec, std::uint32_t i) {
      rec.idx = i;
      VoxelOf(cloud.points[i], voxel_m, &rec.key);
    }, threads);
    tbb::parallel_sort(recs.begin(), recs.end());
    return Reduce(cloud, recs, threads);
  }
  auto packed_key = [&](const PointXYZI& p) {
    Index3 k{0, 0, 0};
    VoxelOf(p, voxel_m, &k);
    return (std::uint64_t(k[0] - b.lo[0]) << (width[1] + width[2])) | (std::uint64_t(k[1] - b.lo[1]) << width[2]) |
           std::uint64_t(k[2] - b.lo[2]);
  };
  PointCloud merged;
  if (runs && all_finite && ReduceRuns(cloud, *runs, packed_key, &merged, threads)) return merged;
  auto recs = Records<PackedRec>(b.finite, point_index,
                                 [&](PackedRec& rec, std::uint32_t i) { rec = {packed_key(cloud.points[i]), i}; }, threads);
  // One thread radix-sorts; else a parallel comparison sort.
  if (threads == 1) RadixSort(recs, width[0] + width[1] + width[2]);
  else tbb::parallel_sort(recs.begin(), recs.end());
  return Reduce(cloud, recs, threads);
}

PointCloud Run(const PointCloud& cloud, double voxel_m, int threads, const std::vector<std::size_t>* runs) {
  if (!(voxel_m > 0.0) || !std::isfinite(voxel_m))
    throw Error("VoxelDownsample: voxel size must be a positive finite number, got " +
                std::to_string(voxel_m));
  if (threads < 0) throw Error("VoxelDownsample: threads must be >= 0, got " + std::to_string(threads));
  cloud.CheckConsistent("VoxelDownsample");
  if (cloud.size() > std::numeric_limits<std::uint32_t>::max())
    throw Error("VoxelDownsample: more than 2^32 points");
  if (cloud.empty()) return PointCloud{};
  // The arena bounds what is no loop (the bounds' parallel_reduce, parallel_sort); the loops
  // take `threads` themselves (ltm::ParallelFor).
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  PointCloud out;
  arena.execute([&] { out = Downsample(cloud, voxel_m, threads, runs); });
  return out;
}

}  // namespace

PointCloud VoxelDownsample(const PointCloud& cloud, double voxel_m, int threads) {
  return Run(cloud, voxel_m, threads, nullptr);
}

PointCloud VoxelDownsampleRuns(const PointCloud& cloud, const std::vector<std::size_t>& run_starts, double voxel_m,
                               int threads) {
  for (std::size_t r = 0; r < run_starts.size(); ++r)
    if ((r == 0 && run_starts[r] != 0) || (r > 0 && run_starts[r] < run_starts[r - 1]) ||
        run_starts[r] > cloud.size())
      throw Error("VoxelDownsampleRuns: run starts must ascend from 0 within the cloud");
  return Run(cloud, voxel_m, threads, run_starts.empty() ? nullptr : &run_starts);
}

}  // namespace ltm::geometry
