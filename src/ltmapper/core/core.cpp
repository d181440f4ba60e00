#include "ltmapper/core/core.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <fstream>
#include <iomanip>
#include <mutex>
#include <sstream>

namespace ltm {

double UpperMedian(std::vector<double>& v) {
  const auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

Error::Error(const std::string& file, std::size_t line, const std::string& what)
    : std::runtime_error(file + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " +
                         what) {}

const char* ToString(PointClass c) {
  switch (c) {
    case PointClass::kUnknown: return "unknown";
    case PointClass::kStatic: return "static";
    case PointClass::kHD: return "hd";
    case PointClass::kPDStrong: return "pd_strong";
    case PointClass::kPDWeak: return "pd_weak";
    case PointClass::kNDStrong: return "nd_strong";
    case PointClass::kNDWeak: return "nd_weak";
  }
  return "unknown";
}

// ------------------------------------------------------------------------------- PointCloud
void PointCloud::clear() {
  points.clear();
  cls.clear();
  session.clear();
  object.clear();
  time.clear();
}

namespace {
template <class T>
void AppendArray(std::vector<T>& dst, const std::vector<T>& src, std::size_t dst_size_before,
                 std::size_t src_size) {
  if (src.empty() && dst.empty()) return;
  // Only keep an optional array when both sides have it (or the destination was empty).
  if (dst.empty() && dst_size_before == 0) {
    dst = src;
    return;
  }
  if (src.empty() || dst.size() != dst_size_before) {
    dst.clear();
    return;
  }
  (void)src_size;
  dst.insert(dst.end(), src.begin(), src.end());
}

template <class T, class Pred>
std::vector<T> Pick(const std::vector<T>& v, std::size_t n, Pred keep) {
  std::vector<T> out;
  if (v.empty()) return out;
  out.reserve(n);
  for (std::size_t i = 0; i < v.size(); ++i)
    if (keep(i)) out.push_back(v[i]);
  return out;
}
}  // namespace

void PointCloud::append(const PointCloud& other) {
  if (other.empty()) return;  // nothing to add: keep this cloud's arrays (an empty part has none)
  const std::size_t before = size();
  AppendArray(cls, other.cls, before, other.size());
  AppendArray(session, other.session, before, other.size());
  AppendArray(object, other.object, before, other.size());
  AppendArray(time, other.time, before, other.size());
  points.insert(points.end(), other.points.begin(), other.points.end());
}

namespace {
// Part k's array copied to `dst` at `at[k]` when every non-empty part has the array; else `dst`
// stays empty.
template <class T>
void ConcatenateArray(std::vector<T> PointCloud::*array, const std::vector<PointCloud>& parts,
                      const std::vector<std::size_t>& at, std::size_t n, int threads, std::vector<T>* dst) {
  for (const PointCloud& part : parts)
    if (!part.empty() && (part.*array).empty()) return;
  dst->resize(n);
  constexpr std::size_t kPiece = std::size_t(1) << 16;  // elements a task copies: a big part on many cores
  std::vector<std::pair<std::size_t, std::size_t>> pieces;  // (part, first element)
  for (std::size_t k = 0; k < parts.size(); ++k)
    for (std::size_t b = 0; b < parts[k].size(); b += kPiece) pieces.emplace_back(k, b);
  ParallelFor(pieces.size(), threads, [&](std::size_t t) {
    const auto [k, b] = pieces[t];
    const std::vector<T>& src = parts[k].*array;
    const std::size_t e = std::min(src.size(), b + kPiece);
    std::copy(src.begin() + std::ptrdiff_t(b), src.begin() + std::ptrdiff_t(e), dst->begin() + std::ptrdiff_t(at[k] + b));
  });
}
}  // namespace

PointCloud Concatenate(std::vector<PointCloud> parts, int threads) {
  std::vector<PointCloud> kept;
  for (PointCloud& part : parts)
    if (!part.empty()) kept.push_back(std::move(part));
  if (kept.size() == 1) return std::move(kept.front());
  std::vector<std::size_t> at(kept.size() + 1, 0);
  for (std::size_t k = 0; k < kept.size(); ++k) at[k + 1] = at[k] + kept[k].size();
  const std::size_t n = at.back();
  PointCloud out;
  ConcatenateArray(&PointCloud::points, kept, at, n, threads, &out.points);
  ConcatenateArray(&PointCloud::cls, kept, at, n, threads, &out.cls);
  ConcatenateArray(&PointCloud::session, kept, at, n, threads, &out.session);
  ConcatenateArray(&PointCloud::object, kept, at, n, threads, &out.object);
  ConcatenateArray(&PointCloud::time, kept, at, n, threads, &out.time);
  return out;
}

PointCloud PointCloud::select(const std::vector<bool>& mask) const {
  if (mask.size() != size())
    throw Error("PointCloud::select: mask has " + std::to_string(mask.size()) +
                " entries for " + std::to_string(size()) + " points");
  const std::size_t n = static_cast<std::size_t>(std::count(mask.begin(), mask.end(), true));
  auto keep = [&](std::size_t i) { return static_cast<bool>(mask[i]); };
  PointCloud out;
  out.points = Pick(points, n, keep);
  out.cls = Pick(cls, n, keep);
  out.session = Pick(session, n, keep);
  out.object = Pick(object, n, keep);
  out.time = Pick(time, n, keep);
  return out;
}

PointCloud PointCloud::select(const std::vector<std::uint32_t>& indices) const {
  PointCloud out;
  out.points.reserve(indices.size());
  for (auto i : indices) {
    if (i >= size()) throw Error("PointCloud::select: index " + std::to_string(i) + " out of range");
    out.points.push_back(points[i]);
    if (!cls.empty()) out.cls.push_back(cls[i]);
    if (!session.empty()) out.session.push_back(session[i]);
    if (!object.empty()) out.object.push_back(object[i]);
    if (!time.empty()) out.time.push_back(time[i]);
  }
  return out;
}

void PointCloud::CheckConsistent(const std::string& what) const {
  auto check = [&](std::size_t n, const char* name) {
    if (n != 0 && n != size())
      throw Error(what + ": per-point array '" + name + "' has " + std::to_string(n) +
                  " entries for " + std::to_string(size()) + " points");
  };
  check(cls.size(), "class");
  check(session.size(), "session");
  check(object.size(), "object");
  check(time.size(), "time");
}

int Session::Find(int index) const {
  auto it = std::lower_bound(keyframes.begin(), keyframes.end(), index,
                             [](const Keyframe& k, int i) { return k.index < i; });
  if (it == keyframes.end() || it->index != index) return -1;
  return static_cast<int>(it - keyframes.begin());
}

// ----------------------------------------------------------------------------------- Config
void ConfigFields::operator()(const std::string& key, double& v, const std::string& unit,
                              double lo, double hi) {
  fields_.push_back({key, ConfigField::Kind::kDouble, &v, unit, lo, hi, {}});
}
void ConfigFields::operator()(const std::string& key, int& v, const std::string& unit, int lo,
                              int hi) {
  fields_.push_back({key, ConfigField::Kind::kInt, &v, unit, double(lo), double(hi), {}});
}
void ConfigFields::operator()(const std::string& key, bool& v) {
  fields_.push_back({key, ConfigField::Kind::kBool, &v, "", 0, 1, {}});
}
void ConfigFields::operator()(const std::string& key, std::string& v,
                              std::vector<std::string> choices) {
  fields_.push_back({key, ConfigField::Kind::kString, &v, "", 0, 0, std::move(choices)});
}
void ConfigFields::operator()(const std::string& key, std::vector<double>& v,
                              const std::string& unit, double lo, double hi, bool allow_empty) {
  fields_.push_back({key, ConfigField::Kind::kDoubleList, &v, unit, lo, hi, {}, allow_empty});
}

namespace {
std::string Num(double v) {
  std::ostringstream os;
  os << std::setprecision(10) << v;
  return os.str();
}
void CheckRange(const ConfigField& f, double v, const std::string& where) {
  if (!std::isfinite(v) || v < f.lo || v > f.hi)
    throw Error(where + ": key '" + f.key + "' = " + Num(v) + " is out of range [" + Num(f.lo) +
                ", " + Num(f.hi) + "]" + (f.unit.empty() ? "" : " " + f.unit));
}
}  // namespace

void ValidateFields(const ConfigFields& fields, const std::string& where) {
  for (const auto& f : fields.fields()) {
    switch (f.kind) {
      case ConfigField::Kind::kDouble: CheckRange(f, *static_cast<double*>(f.ptr), where); break;
      case ConfigField::Kind::kInt: CheckRange(f, *static_cast<int*>(f.ptr), where); break;
      case ConfigField::Kind::kBool: break;
      case ConfigField::Kind::kString: {
        const auto& s = *static_cast<std::string*>(f.ptr);
        if (!f.choices.empty() &&
            std::find(f.choices.begin(), f.choices.end(), s) == f.choices.end()) {
          std::string allowed;
          for (const auto& c : f.choices) allowed += (allowed.empty() ? "" : ", ") + c;
          throw Error(where + ": key '" + f.key + "' = '" + s + "' is not one of: " + allowed);
        }
        break;
      }
      case ConfigField::Kind::kDoubleList: {
        const auto& list = *static_cast<std::vector<double>*>(f.ptr);
        if (list.empty() && !f.allow_empty) throw Error(where + ": key '" + f.key + "' must not be an empty list");
        for (double v : list) CheckRange(f, v, where);
        break;
      }
    }
  }
}

void SetField(const ConfigFields& fields, const std::string& kv) {
  const auto eq = kv.find('=');
  if (eq == std::string::npos) throw Error("--set " + kv + ": expected key=value");
  const std::string key = kv.substr(0, eq), value = kv.substr(eq + 1);
  auto number = [&](const std::string& t) {
    std::size_t used = 0;
    double d = 0.0;
    try {
      d = std::stod(t, &used);
    } catch (const std::logic_error&) {
      used = 0;
    }
    if (used == 0 || used != t.size()) throw Error("--set " + kv + ": '" + t + "' is not a number for key '" + key + "'");
    return d;
  };
  for (const auto& f : fields.fields()) {
    if (f.key != key) continue;
    switch (f.kind) {
      case ConfigField::Kind::kDouble: *static_cast<double*>(f.ptr) = number(value); break;
      case ConfigField::Kind::kInt: {
        const double d = number(value);
        if (d != std::floor(d)) throw Error("--set " + kv + ": key '" + key + "' needs an integer");
        *static_cast<int*>(f.ptr) = static_cast<int>(d);
        break;
      }
      case ConfigField::Kind::kBool:
        if (value != "true" && value != "false") throw Error("--set " + kv + ": key '" + key + "' needs true|false");
        *static_cast<bool*>(f.ptr) = value == "true";
        break;
      case ConfigField::Kind::kString: *static_cast<std::string*>(f.ptr) = value; break;
      case ConfigField::Kind::kDoubleList: {
        // "0.4,0.8" or YAML's flow form "[0.4, 0.8]".
        std::string items = value;
        if (items.size() >= 2 && items.front() == '[' && items.back() == ']') items = items.substr(1, items.size() - 2);
        std::vector<double> list;
        std::stringstream ss(items);
        std::string item;
        while (std::getline(ss, item, ',')) list.push_back(number(item));
        *static_cast<std::vector<double>*>(f.ptr) = list;
        break;
      }
    }
    return;
  }
  std::string known;
  for (const auto& f : fields.fields()) known += (known.empty() ? "" : ", ") + f.key;
  throw Error("--set " + kv + ": unknown key '" + key + "' (keys: " + known + ")");
}

std::string FieldsToString(const ConfigFields& fields) {
  std::ostringstream os;
  for (const auto& f : fields.fields()) {
    os << "  " << f.key << ": ";
    switch (f.kind) {
      case ConfigField::Kind::kDouble: os << Num(*static_cast<double*>(f.ptr)); break;
      case ConfigField::Kind::kInt: os << *static_cast<int*>(f.ptr); break;
      case ConfigField::Kind::kBool: os << (*static_cast<bool*>(f.ptr) ? "true" : "false"); break;
      case ConfigField::Kind::kString: os << *static_cast<std::string*>(f.ptr); break;
      case ConfigField::Kind::kDoubleList: {
        os << "[";
        const auto& list = *static_cast<std::vector<double>*>(f.ptr);
        for (std::size_t i = 0; i < list.size(); ++i) os << (i ? ", " : "") << Num(list[i]);
        os << "]";
        break;
      }
    }
    if (!f.unit.empty()) os << "  # " << f.unit;
    os << "\n";
  }
  return os.str();
}

// --------------------------------------------------------------------------------- Progress
struct Progress::Impl {
  std::string label;
  std::size_t total = 0;
  std::atomic<std::size_t> done{0};
  bool enabled = false;
  bool finished = false;
  std::mutex mu;
  std::chrono::steady_clock::time_point start, last_print;
};

Progress::Progress(std::string label, std::size_t total, bool force) : impl_(new Impl) {
  impl_->label = std::move(label);
  impl_->total = total;
  impl_->enabled = force || isatty(STDERR_FILENO);
  impl_->start = impl_->last_print = std::chrono::steady_clock::now();
}

Progress::~Progress() { Done(); }

void Progress::Tick(std::size_t n) {
  const std::size_t d = impl_->done.fetch_add(n) + n;
  if (!impl_->enabled) return;
  const auto now = std::chrono::steady_clock::now();
  std::unique_lock<std::mutex> lock(impl_->mu, std::try_to_lock);
  if (!lock.owns_lock() || now - impl_->last_print < std::chrono::milliseconds(250)) return;
  impl_->last_print = now;
  const double s = std::chrono::duration<double>(now - impl_->start).count();
  const double rate = s > 0 ? d / s : 0.0;
  const double eta = rate > 0 && impl_->total > d ? (impl_->total - d) / rate : 0.0;
  std::fprintf(stderr, "\r%s: %zu/%zu (%.1f/s, ETA %.0f s)   ", impl_->label.c_str(), d,
               impl_->total, rate, eta);
  std::fflush(stderr);
}

void Progress::Done() {
  if (!impl_ || impl_->finished) return;
  impl_->finished = true;
  if (!impl_->enabled) return;
  const double s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - impl_->start).count();
  std::fprintf(stderr, "\r%s: %zu/%zu in %.1f s                \n", impl_->label.c_str(),
               impl_->done.load(), impl_->total, s);
}

std::size_t PeakRssBytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) {
      std::istringstream is(line.substr(6));
      std::size_t kb = 0;
      is >> kb;
      return kb * 1024;
    }
  }
  return 0;
}

void ParallelForChunks(std::size_t n, int threads, std::size_t grain,
                       const std::function<void(std::size_t begin, std::size_t end)>& f) {
  if (n == 0) return;
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::max<std::size_t>(grain, 1)),
                      [&](const tbb::blocked_range<std::size_t>& r) { f(r.begin(), r.end()); });
  });
}

void ParallelFor(std::size_t n, int threads, const std::function<void(std::size_t)>& f) {
  ParallelForChunks(n, threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i != end; ++i) f(i);
  });
}

void OrderedPipeline(std::size_t n, int threads, std::size_t window, const std::function<void(std::size_t)>& load,
                     const std::function<void(std::size_t)>& work, const std::function<void(std::size_t)>& write) {
  if (threads == 1) {
    for (std::size_t i = 0; i < n; ++i) load(i), work(i), write(i);
    return;
  }
  window = std::max<std::size_t>(window, 1);
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    std::deque<tbb::task_group> running;  // items [written, loaded)
    std::size_t loaded = 0;
    try {
      for (std::size_t i = 0; i < n; ++i) {
        for (; loaded < n && loaded < i + window; ++loaded) {
          load(loaded);
          running.emplace_back();
          running.back().run([&work, k = loaded] { work(k); });
        }
        running.front().wait();  // works on other items meanwhile; rethrows work(i)'s exception
        running.pop_front();
        write(i);
      }
    } catch (...) {
      for (auto& g : running) g.cancel();
      for (auto& g : running) {
        try {
          g.wait();
        } catch (...) {  // the first exception is the one reported
        }
      }
      throw;
    }
  });
}

DistinctCounter::DistinctCounter() : registers_(std::size_t(1) << kBits, 0) {}

void DistinctCounter::Add(std::uint64_t hash) {
  const std::size_t slot = std::size_t(hash >> (64 - kBits));
  const std::uint64_t rest = hash << kBits;  // the other 54 bits, leftmost first
  const int rank = rest == 0 ? 64 - kBits + 1 : __builtin_clzll(rest) + 1;
  registers_[slot] = std::max(registers_[slot], std::uint8_t(rank));
}

void DistinctCounter::Merge(const DistinctCounter& other) {
  for (std::size_t i = 0; i < registers_.size(); ++i) registers_[i] = std::max(registers_[i], other.registers_[i]);
}

double DistinctCounter::Estimate() const {
  const double m = double(registers_.size());
  double inverse_sum = 0.0;
  std::size_t zeros = 0;
  for (std::uint8_t r : registers_) {
    inverse_sum += std::ldexp(1.0, -int(r));
    zeros += r == 0 ? 1 : 0;
  }
  const double raw = 0.7213 / (1.0 + 1.079 / m) * m * m / inverse_sum;
  // Small sets: linear counting over the empty registers is the better estimate.
  if (raw <= 2.5 * m && zeros > 0) return m * std::log(m / double(zeros));
  return raw;
}

std::uint64_t MixHash(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace ltm
