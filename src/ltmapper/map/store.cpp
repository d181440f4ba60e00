// The map store: one SQLite file (WAL, foreign keys, schema version), integration transactions,
// restore / live / meta by composition, fsck and digest. Schema in README.md.
#include "ltmapper/map/detail.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <fcntl.h>
#include <sqlite3.h>
#include <unistd.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <limits>
#include <filesystem>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <sstream>

namespace ltm::map {

using detail::QCloud;
using detail::QPoint;

namespace {

// Schema versions: 2 seeds blob checksums with FNV-1a's offset basis (blob version 2); 1 with a
// truncated one. Version 1 stores still open (their blobs keep version 1 and verify with the old
// basis); the first integration into one marks it version 2, since it adds version 2 blobs.
// Version 3 adds step_records (derived per-step records: the object cache); older stores read
// without it (objects are computed) and get the table with their first write. Version 4 adds
// trajectories (each session's keyframe poses); older stores read without them and get the table
// with their first write.
constexpr int kSchemaVersion = 4;
constexpr int kOldestSchemaVersion = 1;
constexpr int kApplicationId = 0x4C544D50;  // "LTMP"

const char* kSchema = R"sql(
CREATE TABLE schema_info(
  key   TEXT PRIMARY KEY,
  value TEXT NOT NULL);
CREATE TABLE sessions(
  id             INTEGER PRIMARY KEY,            -- order: 0 = central
  name           TEXT NOT NULL UNIQUE,
  reference      INTEGER REFERENCES sessions(id),-- NULL for the central session
  anchor         TEXT NOT NULL,                  -- 3x4 row-major, 12 numbers
  params         TEXT NOT NULL,
  integrated_utc TEXT NOT NULL,
  keyframes_new INTEGER NOT NULL DEFAULT 0, keyframes_changed INTEGER NOT NULL DEFAULT 0,
  pd_strong INTEGER NOT NULL DEFAULT 0, pd_weak INTEGER NOT NULL DEFAULT 0,
  nd_strong INTEGER NOT NULL DEFAULT 0, nd_weak INTEGER NOT NULL DEFAULT 0,
  superseded INTEGER NOT NULL DEFAULT 0, restored INTEGER NOT NULL DEFAULT 0,
  points INTEGER NOT NULL DEFAULT 0, bytes INTEGER NOT NULL DEFAULT 0);
CREATE TABLE keyframes(
  id           INTEGER PRIMARY KEY,
  session      INTEGER NOT NULL REFERENCES sessions(id),
  source_index INTEGER NOT NULL,
  pose         TEXT NOT NULL,                    -- T_world_sensor 3x4 row-major
  UNIQUE(session, source_index));
CREATE TABLE base_clouds(
  keyframe INTEGER PRIMARY KEY REFERENCES keyframes(id),
  as_of    INTEGER NOT NULL REFERENCES sessions(id),
  points   INTEGER NOT NULL,
  data     BLOB NOT NULL);
CREATE TABLE deltas(
  keyframe INTEGER NOT NULL REFERENCES keyframes(id),
  session  INTEGER NOT NULL REFERENCES sessions(id),
  added    INTEGER NOT NULL,
  removed  INTEGER NOT NULL,
  info     INTEGER NOT NULL,
  data     BLOB NOT NULL,
  PRIMARY KEY(keyframe, session));
CREATE INDEX deltas_by_session ON deltas(session);
)sql";
// Where each session's sensor was (SessionMeta::trajectory): every keyframe, not only those that
// made map keyframes. Made by every write (Transaction), so a store has it from its first
// session on, and an older store with its first write.
const char* kTrajectoriesTable = R"sql(
CREATE TABLE IF NOT EXISTS trajectories(
  session INTEGER NOT NULL REFERENCES sessions(id),
  idx     INTEGER NOT NULL,                      -- position in the session's scan order
  pose    TEXT NOT NULL,                         -- T_world_sensor 3x4 row-major
  PRIMARY KEY(session, idx));
)sql";
// Derived from the rows above and rebuilt from them whenever missing or made with another key
// (never part of Digest()).
const char* kStepRecordsTable = R"sql(
CREATE TABLE IF NOT EXISTS step_records(
  session INTEGER PRIMARY KEY REFERENCES sessions(id),
  key     TEXT NOT NULL,                         -- what the record was made with (config text)
  data    BLOB NOT NULL);                        -- detail::PackBytes
)sql";

constexpr int kBusyTimeoutMs = 10000;  // how long a statement waits for another connection's lock

bool ReadableSchema(const std::string& version) {
  for (int v = kOldestSchemaVersion; v <= kSchemaVersion; ++v)
    if (version == std::to_string(v)) return true;
  return false;
}

std::string PoseToText(const Pose& T) {
  std::string s;
  char buf[32];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) {
      std::snprintf(buf, sizeof(buf), "%.17g", T.matrix()(r, c));
      if (!s.empty()) s += ' ';
      s += buf;
    }
  return s;
}

Pose PoseFromText(const std::string& text, const std::string& where) {
  std::istringstream is(text);
  Pose T = Pose::Identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      if (!(is >> T.matrix()(r, c))) throw Error(where + ": pose needs 12 numbers, got '" + text + "'");
  return T;
}

std::string UtcNow() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// ------------------------------------------------------------------------------ sqlite helpers
class Stmt {
 public:
  Stmt(sqlite3* db, const std::string& sql, const std::string& path) : db_(db), path_(path) {
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &st_, nullptr) != SQLITE_OK)
      throw Error(path + ": SQL prepare failed (" + sqlite3_errmsg(db) + "): " + sql);
  }
  ~Stmt() { sqlite3_finalize(st_); }
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;
  Stmt& Bind(int i, long long v) { return Check(sqlite3_bind_int64(st_, i, v)); }
  Stmt& Bind(int i, const std::string& v) {
    return Check(sqlite3_bind_text(st_, i, v.data(), int(v.size()), SQLITE_TRANSIENT));
  }
  Stmt& BindBlob(int i, const std::string& v) {
    return Check(sqlite3_bind_blob(st_, i, v.data(), int(v.size()), SQLITE_TRANSIENT));
  }
  Stmt& BindNull(int i) { return Check(sqlite3_bind_null(st_, i)); }
  // true while rows come; false when done.
  bool Step() {
    const int rc = sqlite3_step(st_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    throw Error(path_ + ": SQL step failed: " + sqlite3_errmsg(db_));
  }
  void Run() {
    while (Step()) {
    }
    sqlite3_reset(st_);
    sqlite3_clear_bindings(st_);
  }
  void Reset() {
    sqlite3_reset(st_);
    sqlite3_clear_bindings(st_);
  }
  long long Int(int c) const { return sqlite3_column_int64(st_, c); }
  int Columns() const { return sqlite3_column_count(st_); }
  bool Null(int c) const { return sqlite3_column_type(st_, c) == SQLITE_NULL; }
  std::string Text(int c) const {
    const auto* p = sqlite3_column_text(st_, c);
    return p ? std::string(reinterpret_cast<const char*>(p), std::size_t(sqlite3_column_bytes(st_, c))) : std::string();
  }
  std::string Blob(int c) const {
    const void* p = sqlite3_column_blob(st_, c);
    const int n = sqlite3_column_bytes(st_, c);
    return p ? std::string(static_cast<const char*>(p), std::size_t(n)) : std::string();
  }

 private:
  Stmt& Check(int rc) {
    if (rc != SQLITE_OK) throw Error(path_ + ": SQL bind failed: " + sqlite3_errmsg(db_));
    return *this;
  }
  sqlite3* db_;
  std::string path_;
  sqlite3_stmt* st_ = nullptr;
};

PointCloud ToWorld(const QCloud& q, const Pose& T, double res, double istep, const Region& region) {
  PointCloud c = detail::Dequantize(q, res, istep);
  geometry::TransformInPlace(c, T);
  if (region.use_box) c = geometry::CropBox(c, region.lo, region.hi);
  return c;
}

PointCloud Concat(std::vector<PointCloud>& parts, const Region& region, int threads) {
  std::size_t n = 0;
  for (const auto& p : parts) n += p.size();
  PointCloud out;
  out.points.reserve(n);
  out.cls.reserve(n);
  out.session.reserve(n);
  for (auto& p : parts) {
    if (p.empty()) continue;
    out.points.insert(out.points.end(), p.points.begin(), p.points.end());
    out.cls.insert(out.cls.end(), p.cls.begin(), p.cls.end());
    out.session.insert(out.session.end(), p.session.begin(), p.session.end());
    PointCloud().points.swap(p.points);
  }
  if (region.voxel_m > 0 && !out.empty()) out = geometry::VoxelDownsample(out, region.voxel_m, threads);
  return out;
}

}  // namespace

// Keyframe ids [first, last): a range restricts the lookups to those (indexed, no scan of the map).
struct IdRange {
  int first = 0, last = std::numeric_limits<int>::max();
  bool all() const { return first <= 0 && last == std::numeric_limits<int>::max(); }
  std::string Sql(const char* column) const {
    return all() ? std::string()
                 : std::string(" AND ") + column + " >= " + std::to_string(first) + " AND " + column + " < " +
                       std::to_string(last);
  }
};

constexpr int kStreamKeyframes = int(detail::kKeyframesPerBatch);  // per streamed batch of ids

// ====================================================================================== Impl
struct Store::Impl {
  sqlite3* db = nullptr;
  std::string path;
  MapConfig cfg;
  int threads = 0;

  bool read_only = false;
  bool unpublished = false;  // Creation::kUnpublished: no journal, synced by Close()

  ~Impl() {
    if (db && !read_only) ToRollbackJournal();
    if (db) sqlite3_close_v2(db);
  }
  void Close() {
    if (!db) return;
    if (unpublished) {  // one sync of the file as written, then the journal mode of a store at rest
      Exec("PRAGMA synchronous = FULL");
      Exec("PRAGMA journal_mode = DELETE");
      Sync();
    } else if (!read_only) {
      ToRollbackJournal();
    }
    const int rc = sqlite3_close(db);
    db = nullptr;
    if (rc != SQLITE_OK) throw Error(path + ": cannot close the map store (" + sqlite3_errstr(rc) + ")");
  }
  // fsync of the store file (SQLite syncs nothing with synchronous = OFF).
  void Sync() const {
    const int fd = ::open(path.c_str(), O_RDONLY);
    const bool ok = fd >= 0 && ::fsync(fd) == 0;
    if (fd >= 0) ::close(fd);
    if (!ok) throw Error(path + ": cannot sync the map store to disk: " + std::strerror(errno));
  }
  // At rest the store is in rollback-journal mode, so a read-only reader (read-only media,
  // another user's store) needs no -wal / -shm and creates none. Best effort: while another
  // connection is open the switch fails and the store stays in WAL mode (all committed data is
  // already in the file: Checkpoint() after each integration).
  void ToRollbackJournal() {
    sqlite3_busy_timeout(db, 0);
    sqlite3_exec(db, "PRAGMA journal_mode = DELETE", nullptr, nullptr, nullptr);
  }
  void Exec(const std::string& sql) const {
    char* err = nullptr;
    if (sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
      const std::string msg = err ? err : "unknown";
      sqlite3_free(err);
      throw Error(path + ": SQL failed (" + msg + "): " + sql.substr(0, 80));
    }
  }
  std::string Pragma(const std::string& name) const {
    Stmt st(db, "PRAGMA " + name, path);
    return st.Step() ? st.Text(0) : std::string();
  }
  void OpenDb(int flags) {
    read_only = (flags & SQLITE_OPEN_READONLY) != 0;
    if (sqlite3_open_v2(path.c_str(), &db, flags, nullptr) != SQLITE_OK) {
      const std::string msg = db ? sqlite3_errmsg(db) : "out of memory";
      throw Error(path + ": cannot open map store" + (read_only ? " read-only: " : ": ") + msg);
    }
    sqlite3_extended_result_codes(db, 1);
    sqlite3_busy_timeout(db, kBusyTimeoutMs);
    Exec("PRAGMA foreign_keys = ON");
    if (read_only) return;  // readers write nothing: no journal mode switch
    if (unpublished) {  // no reader, and a crash discards the file: no journal, no sync until Close()
      Exec("PRAGMA journal_mode = OFF");
      Exec("PRAGMA synchronous = OFF");
      return;
    }
    const std::string mode = Pragma("journal_mode = WAL");
    if (mode != "wal") throw Error(path + ": cannot switch the map store to WAL (journal_mode = " + mode + ")");
    // FULL: a committed integration survives power loss, not only a killed process.
    Exec("PRAGMA synchronous = FULL");
    // A -wal left by an earlier integration whose checkpoint failed (full disk) goes into the
    // file now, or this open is the same error: a writer that then had nothing to integrate
    // exited 0 with that data still only in -wal.
    Checkpoint();
  }
  // Copies the WAL into the store file and empties it, so the file alone holds every committed
  // integration; a full disk or a reader holding the WAL is an error, not a WAL-only success.
  void Checkpoint() const {
    int wal_frames = 0, copied = 0;
    const int rc = sqlite3_wal_checkpoint_v2(db, nullptr, SQLITE_CHECKPOINT_TRUNCATE, &wal_frames, &copied);
    if (rc != SQLITE_OK || copied != wal_frames)
      throw Error(path + ": the integration is committed but could not be copied from " + path +
                  "-wal into the store file (" + (rc == SQLITE_OK ? "incomplete" : sqlite3_errmsg(db)) +
                  "); keep the -wal file next to the store and run the command again");
  }
  bool HasTable(const std::string& name) const;
  bool HasStepRecords() const;  // false for stores of schema 1-2 never written since
  std::string Info(const std::string& key) const {
    Stmt st(db, "SELECT value FROM schema_info WHERE key = ?", path);
    st.Bind(1, key);
    if (!st.Step()) throw Error(path + ": map store has no '" + key + "' in schema_info");
    return st.Text(0);
  }
  std::vector<KeyframeRecord> Keyframes() const {
    std::vector<KeyframeRecord> out;
    Stmt st(db,
            "SELECT k.id, k.session, k.source_index, k.pose, b.points, length(b.data), "
            "(SELECT count(*) FROM deltas d WHERE d.keyframe = k.id), "
            "(SELECT coalesce(sum(length(d.data)), 0) FROM deltas d WHERE d.keyframe = k.id) "
            "FROM keyframes k LEFT JOIN base_clouds b ON b.keyframe = k.id ORDER BY k.id",
            path);
    while (st.Step()) {
      KeyframeRecord r;
      r.id = int(st.Int(0));
      r.session = int(st.Int(1));
      r.source_index = int(st.Int(2));
      r.T_world_sensor = PoseFromText(st.Text(3), path + ": keyframe " + std::to_string(r.id));
      r.base_points = std::size_t(st.Int(4));
      r.base_bytes = std::size_t(st.Int(5));
      r.delta_count = std::size_t(st.Int(6));
      r.delta_bytes = std::size_t(st.Int(7));
      out.push_back(r);
    }
    return out;
  }
  int Latest() const {
    Stmt st(db, "SELECT max(id) FROM sessions", path);
    st.Step();
    return st.Null(0) ? -1 : int(st.Int(0));
  }
  QCloud Decode(const std::string& blob, const std::string& what) const {
    return detail::DecodeQ(blob.data(), blob.size(), path + ": " + what);
  }
  std::string Encode(const QCloud& q) const { return detail::EncodeQ(q, cfg.resolution_m, cfg.intensity_step, cfg.zstd_level); }

  // Base blob and the deltas with session > min_session, newest first.
  struct KfBlobs {
    KeyframeRecord rec;
    std::string base;
    std::vector<std::pair<int, std::string>> deltas;  // (session, blob), newest first
  };
  std::vector<KfBlobs> LoadBlobs(int max_created_session, int min_delta_session, int only_delta_session = -1,
                                 IdRange ids = {}) const {
    std::vector<KfBlobs> out;
    std::map<int, std::size_t> pos;
    const std::string kf_filter = ids.Sql("keyframe");
    {
      Stmt st(db,
              "SELECT id, session, source_index, pose FROM keyframes WHERE session <= ?" + ids.Sql("id") +
                  " ORDER BY id",
              path);
      st.Bind(1, max_created_session);
      while (st.Step()) {
        KfBlobs b;
        b.rec.id = int(st.Int(0));
        b.rec.session = int(st.Int(1));
        b.rec.source_index = int(st.Int(2));
        b.rec.T_world_sensor = PoseFromText(st.Text(3), path + ": keyframe " + std::to_string(b.rec.id));
        pos[b.rec.id] = out.size();
        out.push_back(std::move(b));
      }
    }
    if (only_delta_session < 0) {
      Stmt st(db, "SELECT keyframe, data FROM base_clouds WHERE 1" + kf_filter, path);
      while (st.Step()) {
        auto it = pos.find(int(st.Int(0)));
        if (it != pos.end()) out[it->second].base = st.Blob(1);
      }
    }
    Stmt sd(db,
            only_delta_session >= 0 ? "SELECT keyframe, session, data FROM deltas WHERE session = ?" + kf_filter
                                    : "SELECT keyframe, session, data FROM deltas WHERE session > ?" + kf_filter +
                                          " ORDER BY session DESC",
            path);
    sd.Bind(1, only_delta_session >= 0 ? only_delta_session : min_delta_session);
    while (sd.Step()) {
      auto it = pos.find(int(sd.Int(0)));
      if (it != pos.end()) out[it->second].deltas.emplace_back(int(sd.Int(1)), sd.Blob(2));
    }
    return out;
  }
  // Each keyframe's part (`part` of its blobs) in id order, handed to `sink`: kStreamKeyframes
  // keyframes are loaded and made into parts (in parallel) at a time, so memory is such a batch,
  // not the map.
  // part(keyframe) of every keyframe created up to max_created_session (deltas above
  // min_delta_session loaded), handed to `sink` in id order on this thread. The keyframes are read
  // kStreamKeyframes at a time on this thread too, while the parts of the ones before are computed
  // on the workers (ltm::OrderedPipeline): at most kStreamKeyframes parts in flight (twice as many
  // cost 30 % more peak on the demo's store for no speed), a large keyframe holds up no batch.
  void StreamParts(int max_created_session, int min_delta_session, const std::function<PointCloud(const KfBlobs&)>& part,
                   const PartSink& sink) const {
    std::vector<int> ids;
    {
      Stmt st(db, "SELECT id FROM keyframes WHERE session <= ? ORDER BY id", path);
      st.Bind(1, max_created_session);
      while (st.Step()) ids.push_back(int(st.Int(0)));
    }
    const std::size_t window = std::size_t(kStreamKeyframes);
    struct Slot {
      KfBlobs in;
      PointCloud out;
    };
    // Item i in slot i % size (OrderedPipeline): one batch more than the window, as a batch is read
    // ahead of it.
    std::vector<Slot> ring(std::min(ids.size(), window + std::size_t(kStreamKeyframes)));
    std::size_t fetched = 0;  // items [0, fetched) read from the store
    const auto load = [&](std::size_t i) {
      if (i < fetched) return;
      std::vector<KfBlobs> batch =
          LoadBlobs(max_created_session, min_delta_session, -1, {ids[i], ids[i] + kStreamKeyframes});
      if (batch.empty() || batch.front().rec.id != ids[i] || i + batch.size() > ids.size())
        throw Error(path + ": the store's keyframes changed while they were read");
      for (KfBlobs& b : batch) ring[fetched++ % ring.size()].in = std::move(b);
    };
    const auto work = [&](std::size_t i) {
      Slot& x = ring[i % ring.size()];
      x.out = part(x.in);
      x.in = {};
    };
    const auto write = [&](std::size_t i) {
      Slot& x = ring[i % ring.size()];
      sink(std::move(x.out));
      x.out = {};
    };
    OrderedPipeline(ids.size(), threads, window, load, work, write);
  }
  // LoadBlobs(max_created_session, min_delta_session) kStreamKeyframes keyframe ids at a time,
  // in id order, over the ids of `ids` (default: every keyframe): memory is a batch, not the map.
  void ForEachBatch(int max_created_session, int min_delta_session,
                    const std::function<void(const std::vector<KfBlobs>&)>& batch, IdRange ids = {}) const {
    if (ids.all()) {
      Stmt st(db, "SELECT max(id) FROM keyframes", path);
      st.Step();
      ids.last = st.Null(0) ? 0 : int(st.Int(0)) + 1;
    }
    for (int first = ids.first; first < ids.last; first += kStreamKeyframes)
      batch(LoadBlobs(max_created_session, min_delta_session, -1, {first, std::min(first + kStreamKeyframes, ids.last)}));
  }
  // State as of the oldest session above which deltas were loaded (inverse chain from the base).
  QCloud Rollback(const KfBlobs& b) const {
    const std::string what = "keyframe " + std::to_string(b.rec.id);
    QCloud s = Decode(b.base, what + " base");
    for (const auto& [session, blob] : b.deltas)
      s = detail::ApplyInverse(s, Decode(blob, what + " delta " + std::to_string(session)));
    return s;
  }
};

// ===================================================================================== Store
Store::Store(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Store::Store(Store&&) noexcept = default;
Store& Store::operator=(Store&&) noexcept = default;
Store::~Store() = default;

const std::string& Store::path() const { return impl_->path; }
const MapConfig& Store::config() const { return impl_->cfg; }
void Store::Close() { impl_->Close(); }
void Store::set_threads(int threads) { impl_->threads = threads; }
int Store::threads() const { return impl_->threads; }

Store Store::Create(const std::string& path, const MapConfig& cfg, Creation creation) {
  ValidateConfig(cfg, "map config");
  if (std::filesystem::exists(path)) throw Error(path + ": map store already exists");
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->cfg = cfg;
  impl->unpublished = creation == Creation::kUnpublished;
  impl->OpenDb(SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
  impl->Exec("BEGIN IMMEDIATE");
  try {
    impl->Exec("PRAGMA application_id = " + std::to_string(kApplicationId));
    impl->Exec(kSchema);
    impl->Exec(kStepRecordsTable);
    Stmt ins(impl->db, "INSERT INTO schema_info(key, value) VALUES(?, ?)", path);
    char buf[64];
    const std::pair<std::string, std::string> rows[] = {
        {"schema_version", std::to_string(kSchemaVersion)},
        {"resolution_m", (std::snprintf(buf, sizeof(buf), "%.17g", cfg.resolution_m), std::string(buf))},
        {"intensity_step", (std::snprintf(buf, sizeof(buf), "%.17g", cfg.intensity_step), std::string(buf))},
        {"created_utc", UtcNow()},
        {"generator", "ltmapper 0.1.0"}};
    for (const auto& [k, v] : rows) ins.Bind(1, k).Bind(2, v).Run();
    impl->Exec("COMMIT");
  } catch (...) {
    sqlite3_exec(impl->db, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
  return Store(std::move(impl));
}

Store Store::Open(const std::string& path, const MapConfig& cfg, Access access) {
  ValidateConfig(cfg, "map config");
  if (!std::filesystem::is_regular_file(path)) throw Error(path + ": map store not found");
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->cfg = cfg;
  impl->OpenDb(access == Access::kReadOnly ? SQLITE_OPEN_READONLY : SQLITE_OPEN_READWRITE);
  std::string version;
  try {
    version = impl->Info("schema_version");
  } catch (const Error&) {
    throw Error(path + ": not an ltmapper map store (no schema_info table)");
  }
  if (!ReadableSchema(version))
    throw Error(path + ": map store schema version " + version + ", this ltmapper reads versions " +
                std::to_string(kOldestSchemaVersion) + " to " + std::to_string(kSchemaVersion));
  impl->cfg.resolution_m = std::stod(impl->Info("resolution_m"));
  impl->cfg.intensity_step = std::stod(impl->Info("intensity_step"));
  return Store(std::move(impl));
}

namespace {
// Commits explicitly; rolls back when destroyed without Commit() (exceptions).
class Transaction {
 public:
  // Every write adds current-version blobs, so it marks an older store current.
  explicit Transaction(Store::Impl& s) : s_(s) {
    s_.Exec("BEGIN IMMEDIATE");
    const std::string current = "'" + std::to_string(kSchemaVersion) + "'";
    s_.Exec("UPDATE schema_info SET value = " + current + " WHERE key = 'schema_version' AND value <> " + current);
    s_.Exec(kStepRecordsTable);
    s_.Exec(kTrajectoriesTable);
  }
  // COMMIT, then the checkpoint that puts the committed data into the store file itself.
  void Commit() {
    s_.Exec("COMMIT");
    done_ = true;
    s_.Checkpoint();
  }
  ~Transaction() {
    if (!done_) sqlite3_exec(s_.db, "ROLLBACK", nullptr, nullptr, nullptr);
  }

 private:
  Store::Impl& s_;
  bool done_ = false;
};

void InsertSession(Store::Impl& s, int order, const SessionMeta& meta, int reference) {
  Stmt st(s.db, "INSERT INTO sessions(id, name, reference, anchor, params, integrated_utc) VALUES(?,?,?,?,?,?)", s.path);
  st.Bind(1, order).Bind(2, meta.name);
  if (reference < 0)
    st.BindNull(3);
  else
    st.Bind(3, reference);
  st.Bind(4, PoseToText(meta.anchor)).Bind(5, meta.params).Bind(6, UtcNow()).Run();
  Stmt it(s.db, "INSERT INTO trajectories(session, idx, pose) VALUES(?,?,?)", s.path);
  for (std::size_t k = 0; k < meta.trajectory.size(); ++k)
    it.Bind(1, order).Bind(2, (long long)k).Bind(3, PoseToText(meta.trajectory[k])).Run();
}

void FinishSession(Store::Impl& s, IntegrationResult& r) {
  {
    Stmt st(s.db, "SELECT coalesce(sum(points), 0) FROM base_clouds", s.path);
    st.Step();
    r.points = std::size_t(st.Int(0));
  }
  Stmt st(s.db,
          "UPDATE sessions SET keyframes_new=?, keyframes_changed=?, pd_strong=?, pd_weak=?, nd_strong=?, "
          "nd_weak=?, superseded=?, restored=?, points=?, bytes=? WHERE id=?",
          s.path);
  st.Bind(1, (long long)r.keyframes_new).Bind(2, (long long)r.keyframes_changed);
  st.Bind(3, (long long)r.pd_strong).Bind(4, (long long)r.pd_weak).Bind(5, (long long)r.nd_strong);
  st.Bind(6, (long long)r.nd_weak).Bind(7, (long long)r.superseded).Bind(8, (long long)r.restored);
  st.Bind(9, (long long)r.points).Bind(10, (long long)r.bytes).Bind(11, r.session).Run();
}

void CheckName(const std::string& name) {
  if (name.empty()) throw Error("map store: session name is empty");
}
}  // namespace

KeyframeSource InMemory(const std::vector<KeyframeInput>& keyframes) {
  KeyframeSource src;
  for (const auto& kf : keyframes) src.keyframes.push_back({kf.index, kf.T_world_sensor, kf.cloud.size()});
  src.read = [&keyframes](std::size_t k) { return keyframes[k].cloud; };
  return src;
}

DeltaSource InMemory(const std::vector<KeyframeDelta>& deltas) {
  DeltaSource src;
  for (const auto& d : deltas) src.keyframes.push_back(d.keyframe);
  src.read = [&deltas](std::size_t k) { return deltas[k]; };
  return src;
}

// Map keyframes in flight in a store step (read or encoded, not yet written): the memory bound.
constexpr std::size_t kKeyframesInFlight = 2 * detail::kKeyframesPerBatch;

// Adds the keyframes `which` of `src` (their clouds become bases owned by `session`), in order:
// each read and encoded in parallel while the ones before it are written.
static void InsertKeyframes(Store::Impl& s, Store& store, int session, const KeyframeSource& src,
                            const std::vector<std::size_t>& which, IntegrationResult& r, std::size_t& written) {
  Stmt ik(s.db, "INSERT INTO keyframes(session, source_index, pose) VALUES(?,?,?)", s.path);
  Stmt ib(s.db, "INSERT INTO base_clouds(keyframe, as_of, points, data) VALUES(?,?,?,?)", s.path);
  struct Encoded {
    std::string blob;
    std::size_t points = 0;
  };
  // Item i in slot i % size (OrderedPipeline).
  std::vector<Encoded> slots(std::min(kKeyframesInFlight, which.size()));
  const auto encode = [&](std::size_t i) {
    const KeyframeSlot& kf = src.keyframes[which[i]];
    const QCloud q = detail::Quantize(src.read(which[i]), s.cfg.resolution_m, s.cfg.intensity_step,
                                      PointClass::kStatic, std::uint16_t(session),
                                      "session " + std::to_string(session) + " keyframe " + std::to_string(kf.index));
    slots[i % slots.size()] = {s.Encode(q), q.size()};
  };
  const auto insert = [&](std::size_t i) {
    const KeyframeSlot& kf = src.keyframes[which[i]];
    Encoded& e = slots[i % slots.size()];
    ik.Bind(1, session).Bind(2, kf.index).Bind(3, PoseToText(kf.T_world_sensor)).Run();
    const long long id = sqlite3_last_insert_rowid(s.db);
    ib.Bind(1, id).Bind(2, session).Bind(3, (long long)e.points).BindBlob(4, e.blob).Run();
    r.bytes += e.blob.size();
    e = {};
    ++r.keyframes_new;
    ++written;
    if (store.on_keyframe_written) store.on_keyframe_written(written);
  };
  OrderedPipeline(which.size(), s.threads, slots.size(), [](std::size_t) {}, encode, insert);
}

IntegrationResult Store::IntegrateBase(const SessionMeta& session, const std::vector<KeyframeInput>& keyframes) {
  return IntegrateBaseFrom(session, InMemory(keyframes));
}

IntegrationResult Store::IntegrateBaseFrom(const SessionMeta& session, const KeyframeSource& keyframes) {
  const auto t0 = std::chrono::steady_clock::now();
  CheckName(session.name);
  Impl& s = *impl_;
  Transaction tx(s);
  if (s.Latest() >= 0) throw Error(s.path + ": the store already has a base session");
  IntegrationResult r;
  r.session = 0;
  InsertSession(s, 0, session, -1);
  std::vector<std::size_t> all(keyframes.keyframes.size());
  for (std::size_t k = 0; k < all.size(); ++k) all[k] = k;
  std::size_t written = 0;
  InsertKeyframes(s, *this, 0, keyframes, all, r, written);
  FinishSession(s, r);
  tx.Commit();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

namespace {
// Work per map keyframe: the removert delta (keyframes owned by the reference session) and / or
// query points re-expressed in its frame (query keyframes near it), as positions in the sources.
struct KeyframeWork {
  std::size_t delta = kNone;
  std::vector<std::pair<std::size_t, Pose>> extra;  // query keyframe, T_map_query
  static constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
};
using WorkPlan = std::map<std::size_t, KeyframeWork>;  // by position in the map's keyframes

// What a step reads: the session's sources.
struct StepInputs {
  const DeltaSource& deltas;
  const KeyframeSource& query;
};

// One map keyframe's step: the blobs to write and the counts of the delta's points.
struct KeyframeStep {
  std::string delta_blob, base_blob;
  std::size_t added = 0, removed = 0, info = 0, base_points = 0;
  std::size_t nd_weak_in = 0;  // weak ND points LT-removert reported (stored or not)
  std::size_t pd_strong = 0, pd_weak = 0, nd_strong = 0, superseded = 0, restored = 0;
};

// The step the new session takes (the order after the latest); errors when it cannot be one.
int NewSessionOrder(Store::Impl& s, const SessionMeta& session) {
  const int latest = s.Latest();
  if (latest < 0) throw Error(s.path + ": integrate the central session first (map init)");
  Stmt st(s.db, "SELECT id FROM sessions WHERE name = ?", s.path);
  st.Bind(1, session.name);
  if (st.Step()) throw Error(s.path + ": session '" + session.name + "' is already integrated");
  if (latest + 1 > 65535) throw Error(s.path + ": too many sessions");
  return latest + 1;
}

// LT-removert's delta of each reference keyframe goes to that map keyframe.
void AssignDeltas(const Store::Impl& s, const std::vector<KeyframeRecord>& kfs, int ref, const std::string& reference,
                  const DeltaSource& deltas, WorkPlan* work) {
  std::map<int, std::size_t> owned;  // reference keyframe index -> position in kfs
  for (std::size_t k = 0; k < kfs.size(); ++k)
    if (kfs[k].session == ref) owned[kfs[k].source_index] = k;
  for (std::size_t d = 0; d < deltas.keyframes.size(); ++d) {
    const int keyframe = deltas.keyframes[d];
    const auto it = owned.find(keyframe);
    if (it == owned.end())
      throw Error(s.path + ": delta for keyframe " + std::to_string(keyframe) + " of session '" + reference +
                  "', which is not a map keyframe");
    if ((*work)[it->second].delta != KeyframeWork::kNone)
      throw Error(s.path + ": two deltas for keyframe " + std::to_string(keyframe));
    (*work)[it->second].delta = d;
  }
}

// A query keyframe within new_keyframe_radius_m of a map keyframe adds its cloud to the nearest
// one; the others become new map keyframes (their positions returned), one per place unless they
// carry points.
std::vector<std::size_t> AssignQueryKeyframes(const Store::Impl& s, const std::vector<KeyframeRecord>& kfs,
                                              const KeyframeSource& query, WorkPlan* work) {
  const double r2 = s.cfg.new_keyframe_radius_m * s.cfg.new_keyframe_radius_m;
  std::vector<std::size_t> fresh;
  std::vector<Eigen::Vector3d> fresh_t;
  for (std::size_t qk = 0; qk < query.keyframes.size(); ++qk) {
    const KeyframeSlot& q = query.keyframes[qk];
    const Eigen::Vector3d t = q.T_world_sensor.translation();
    double best = std::numeric_limits<double>::infinity();
    std::size_t m = 0;
    for (std::size_t k = 0; k < kfs.size(); ++k) {
      const double d2 = (kfs[k].T_world_sensor.translation() - t).squaredNorm();
      if (d2 < best) best = d2, m = k;
    }
    bool near_fresh = false;
    for (const auto& f : fresh_t) near_fresh |= (f - t).squaredNorm() <= r2;
    if (best > r2) {
      if (!near_fresh || q.points > 0) {  // keep every point: a cloud near a fresh one is its own
        fresh.push_back(qk);
        fresh_t.push_back(t);
      }
    } else if (q.points > 0) {
      (*work)[m].extra.emplace_back(qk, kfs[m].T_world_sensor.inverse() * q.T_world_sensor);
    }
  }
  return fresh;
}

// Reads a map keyframe's stored blobs: its base and the deltas after the reference's step.
class BlobReader {
 public:
  BlobReader(const Store::Impl& s, int ref)
      : s_(s),
        ref_(ref),
        base_(s.db, "SELECT data FROM base_clouds WHERE keyframe = ?", s.path),
        deltas_(s.db, "SELECT session, data FROM deltas WHERE keyframe = ? AND session > ? ORDER BY session DESC",
                s.path) {}
  Store::Impl::KfBlobs Read(const KeyframeRecord& rec) {
    Store::Impl::KfBlobs in;
    in.rec = rec;
    base_.Bind(1, rec.id);
    if (!base_.Step()) throw Error(s_.path + ": keyframe " + std::to_string(rec.id) + " has no base cloud");
    in.base = base_.Blob(0);
    base_.Reset();
    deltas_.Bind(1, rec.id).Bind(2, ref_);
    while (deltas_.Step()) in.deltas.emplace_back(int(deltas_.Int(0)), deltas_.Blob(1));
    deltas_.Reset();
    return in;
  }

 private:
  const Store::Impl& s_;
  int ref_;
  Stmt base_, deltas_;
};

// The weak ND points of a keyframe's delta in the columns of its strong ND points (within
// `radius_m` of one in xy, at any height): the parts of something that left which the query did
// not see through, under, between and over the parts it saw through (its view of the foot blocked,
// rows between its beams). They change nothing in the map but the objects stage reads them
// (objects.cpp): the unseen parts of an object (UnseenParts), and no surface the step saw
// unchanged in its box (WithoutUnseen). So they are stored even without store_weak_nd.
PointCloud WeakNdInStrongNdColumns(const PointCloud& weak, const PointCloud& strong, double radius_m) {
  if (weak.empty() || strong.empty() || radius_m <= 0.0) return {};
  const auto flat = [](PointCloud c) {  // xy only
    for (auto& p : c.points) p.z = 0.f;
    return c;
  };
  return weak.select(geometry::WithinRadius(flat(weak), flat(strong), radius_m));
}

// The keyframe's target state. A reference keyframe: its state at the reference's step minus the
// strong ND matched within nd_match_radius_m (their keys into change_keys) plus PD (paper eq. 4);
// then the query points near it (new territory seen again, or PD beyond the assignment radius):
// a keyframe the reference never had is replaced by what this session saw.
QCloud TargetState(const Store::Impl& s, const Store::Impl::KfBlobs& in, const KeyframeDelta* delta,
                   const StepInputs& src, const KeyframeWork& w, int ref, int S, const QCloud& latest_q,
                   const std::string& what, detail::KeySet* change_keys, QCloud* nd_weak) {
  auto quant = [&](const PointCloud& c, PointClass cls, const std::string& name) {
    return detail::Quantize(c, s.cfg.resolution_m, s.cfg.intensity_step, cls, std::uint16_t(S), what + " " + name);
  };
  QCloud target;
  if (in.rec.session == ref) {
    const QCloud ref_q = in.deltas.empty() ? latest_q : s.Rollback(in);
    QCloud nd_strong;
    if (delta) {
      nd_strong = quant(delta->nd_strong, PointClass::kNDStrong, "nd_strong");
      // Weak ND changes nothing in the map (occluded, kept); it is stored on request, else only
      // in the columns of strong ND (the unseen parts of an object).
      *nd_weak = quant(s.cfg.store_weak_nd ? delta->nd_weak
                                           : WeakNdInStrongNdColumns(delta->nd_weak, delta->nd_strong, s.cfg.object_tolerance_m),
                       PointClass::kNDWeak, "nd_weak");
    }
    const std::vector<bool> matched = detail::WithinRadiusQ(ref_q, nd_strong, s.cfg.nd_match_radius_m / s.cfg.resolution_m);
    target.reserve(ref_q.size());
    for (std::size_t i = 0; i < ref_q.size(); ++i) {
      if (matched[i])
        change_keys->Insert(detail::Key(ref_q[i]));
      else
        target.push_back(ref_q[i]);
    }
    if (delta) {
      for (const QPoint& p : quant(delta->pd_strong, PointClass::kPDStrong, "pd_strong")) target.push_back(p);
      for (const QPoint& p : quant(delta->pd_weak, PointClass::kPDWeak, "pd_weak")) target.push_back(p);
    }
  }
  for (const auto& [q, T] : w.extra)
    for (const QPoint& p : quant(geometry::Transform(src.query.read(q), T), PointClass::kPDStrong,
                                 "query keyframe " + std::to_string(src.query.keyframes[q].index)))
      target.push_back(p);
  return target;
}

void CountRoles(const QCloud& delta, int S, KeyframeStep* o) {
  for (const QPoint& p : delta) {
    switch (p.role) {
      case detail::kAdded:
        ++o->added;
        if (p.session == S && p.cls == std::uint8_t(PointClass::kPDStrong)) ++o->pd_strong;
        else if (p.session == S && p.cls == std::uint8_t(PointClass::kPDWeak)) ++o->pd_weak;
        else ++o->restored;
        break;
      case detail::kRemovedChange: ++o->removed, ++o->nd_strong; break;
      case detail::kRemovedSuperseded: ++o->removed, ++o->superseded; break;
      default: ++o->info;
    }
  }
}

// The delta from the keyframe's latest state to its target, and the new latest state.
// The keyframe's delta and query clouds are read here, one keyframe's at a time per worker.
KeyframeStep StepKeyframe(const Store::Impl& s, const Store::Impl::KfBlobs& in, const StepInputs& src,
                          const KeyframeWork& w, int ref, int S, const std::string& session_name) {
  const std::string what = "session '" + session_name + "' map keyframe " + std::to_string(in.rec.id);
  const QCloud latest_q = s.Decode(in.base, what + " base");
  KeyframeDelta removert;
  if (w.delta != KeyframeWork::kNone) removert = src.deltas.read(w.delta);
  const KeyframeDelta* d = w.delta != KeyframeWork::kNone ? &removert : nullptr;
  detail::KeySet change_keys;
  QCloud nd_weak;
  const QCloud target = TargetState(s, in, d, src, w, ref, S, latest_q, what, &change_keys, &nd_weak);
  const QCloud delta = detail::MakeDelta(latest_q, target, change_keys, nd_weak);
  KeyframeStep o;
  o.nd_weak_in = d ? d->nd_weak.size() : 0;
  CountRoles(delta, S, &o);
  if (delta.empty()) return o;
  o.delta_blob = s.Encode(delta);
  if (o.added + o.removed > 0) {
    const QCloud next = detail::ApplyForward(latest_q, delta);
    o.base_points = next.size();
    o.base_blob = s.Encode(next);
  }
  return o;
}

// The statements a step's writes use, prepared once per integration.
struct StepWriter {
  explicit StepWriter(const Store::Impl& s)
      : put_delta(s.db, "INSERT INTO deltas(keyframe, session, added, removed, info, data) VALUES(?,?,?,?,?,?)", s.path),
        put_base(s.db, "UPDATE base_clouds SET as_of = ?, points = ?, data = ? WHERE keyframe = ?", s.path) {}

  // Writes one keyframe's step (delta row, new base) and adds its counts to r; false when the
  // step changed nothing.
  bool Write(int keyframe_id, int S, const KeyframeStep& o, IntegrationResult& r) {
    r.nd_weak += o.nd_weak_in;
    if (o.delta_blob.empty()) return false;
    put_delta.Bind(1, keyframe_id).Bind(2, S).Bind(3, (long long)o.added).Bind(4, (long long)o.removed);
    put_delta.Bind(5, (long long)o.info).BindBlob(6, o.delta_blob).Run();
    r.bytes += o.delta_blob.size();
    if (!o.base_blob.empty()) {
      put_base.Bind(1, S).Bind(2, (long long)o.base_points).BindBlob(3, o.base_blob).Bind(4, keyframe_id).Run();
      r.bytes += o.base_blob.size();
      ++r.keyframes_changed;
    }
    r.pd_strong += o.pd_strong;
    r.pd_weak += o.pd_weak;
    r.nd_strong += o.nd_strong;
    r.superseded += o.superseded;
    r.restored += o.restored;
    return true;
  }

  Stmt put_delta, put_base;
};

// The planned map keyframes' steps, the costliest first (the keyframe's points and the query
// points it takes), so that a long one starts at once instead of holding up the writes at the end.
std::vector<std::pair<std::size_t, const KeyframeWork*>> CostliestFirst(const WorkPlan& work,
                                                                        const std::vector<KeyframeRecord>& kfs,
                                                                        const KeyframeSource& query) {
  std::vector<std::pair<std::size_t, const KeyframeWork*>> items;
  std::vector<std::size_t> cost;
  for (const auto& [k, w] : work) {
    items.emplace_back(k, &w);
    cost.push_back(kfs[k].base_points);
    for (const auto& [q, T] : w.extra) cost.back() += query.keyframes[q].points;
  }
  std::vector<std::size_t> order(items.size());
  std::iota(order.begin(), order.end(), std::size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return cost[a] > cost[b]; });
  std::vector<std::pair<std::size_t, const KeyframeWork*>> out;
  for (std::size_t i : order) out.push_back(items[i]);
  return out;
}

// Steps the planned map keyframes: each read from the store, stepped on the workers and written
// in order, at most kKeyframesInFlight at once. Returns how many were written (changed).
std::size_t StepMapKeyframes(Store::Impl& s, const std::vector<KeyframeRecord>& kfs, const WorkPlan& work,
                             const StepInputs& src, int ref, int S, const std::string& session_name,
                             IntegrationResult& r, const std::function<void(std::size_t)>& on_written) {
  const auto items = CostliestFirst(work, kfs, src.query);
  std::size_t written = 0;
  StepWriter writer(s);
  BlobReader reader(s, ref);
  struct InFlight {
    Store::Impl::KfBlobs in;
    KeyframeStep step;
  };
  // Item i in slot i % size (OrderedPipeline).
  std::vector<InFlight> slots(std::min(kKeyframesInFlight, items.size()));
  const auto slot = [&](std::size_t i) -> InFlight& { return slots[i % slots.size()]; };
  const auto load = [&](std::size_t i) { slot(i).in = reader.Read(kfs[items[i].first]); };
  const auto step = [&](std::size_t i) {
    slot(i).step = StepKeyframe(s, slot(i).in, src, *items[i].second, ref, S, session_name);
  };
  const auto write = [&](std::size_t i) {
    InFlight& x = slot(i);
    const bool changed = writer.Write(x.in.rec.id, S, x.step, r);
    x = {};
    if (!changed) return;
    ++written;
    if (on_written) on_written(written);
  };
  OrderedPipeline(items.size(), s.threads, slots.size(), load, step, write);
  return written;
}
}  // namespace

IntegrationResult Store::IntegrateSession(const SessionMeta& session, const std::string& reference,
                                          const std::vector<KeyframeDelta>& deltas,
                                          const std::vector<KeyframeInput>& query_keyframes) {
  return IntegrateSessionFrom(session, reference, InMemory(deltas), InMemory(query_keyframes));
}

IntegrationResult Store::IntegrateSessionFrom(const SessionMeta& session, const std::string& reference,
                                              const DeltaSource& deltas, const KeyframeSource& query_keyframes) {
  const auto t0 = std::chrono::steady_clock::now();
  CheckName(session.name);
  Impl& s = *impl_;
  Transaction tx(s);
  IntegrationResult r;
  const int S = r.session = NewSessionOrder(s, session);
  const int ref = SessionOrder(reference);
  InsertSession(s, S, session, ref);

  const std::vector<KeyframeRecord> kfs = s.Keyframes();
  WorkPlan work;
  AssignDeltas(s, kfs, ref, reference, deltas, &work);
  const std::vector<std::size_t> fresh = AssignQueryKeyframes(s, kfs, query_keyframes, &work);
  const StepInputs src{deltas, query_keyframes};
  std::size_t written = StepMapKeyframes(s, kfs, work, src, ref, S, session.name, r, on_keyframe_written);
  InsertKeyframes(s, *this, S, query_keyframes, fresh, r, written);
  FinishSession(s, r);
  tx.Commit();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

// ================================================================================== queries
std::vector<SessionRecord> Store::Sessions() const {
  const Impl& s = *impl_;
  std::vector<SessionRecord> out;
  Stmt st(s.db,
          "SELECT id, name, reference, anchor, params, integrated_utc, keyframes_new, keyframes_changed, pd_strong, "
          "pd_weak, nd_strong, nd_weak, superseded, restored, points, bytes FROM sessions ORDER BY id",
          s.path);
  while (st.Step()) {
    SessionRecord r;
    r.order = int(st.Int(0));
    r.name = st.Text(1);
    r.reference = st.Null(2) ? -1 : int(st.Int(2));
    r.anchor = PoseFromText(st.Text(3), s.path + ": session " + r.name + " anchor");
    r.params = st.Text(4);
    r.integrated_utc = st.Text(5);
    std::size_t* f[] = {&r.keyframes_new, &r.keyframes_changed, &r.pd_strong, &r.pd_weak, &r.nd_strong,
                        &r.nd_weak,       &r.superseded,        &r.restored,  &r.points,  &r.bytes};
    for (int k = 0; k < 10; ++k) *f[k] = std::size_t(st.Int(6 + k));
    out.push_back(r);
  }
  return out;
}

std::vector<KeyframeRecord> Store::Keyframes() const { return impl_->Keyframes(); }
int Store::LatestSession() const { return impl_->Latest(); }

int Store::SessionOrder(const std::string& name) const {
  Stmt st(impl_->db, "SELECT id FROM sessions WHERE name = ?", impl_->path);
  st.Bind(1, name);
  if (!st.Step()) throw Error(impl_->path + ": no session named '" + name + "' in the map store");
  return int(st.Int(0));
}

StoreTotals Store::Totals() const {
  const Impl& s = *impl_;
  StoreTotals t;
  for (const char* suffix : {"", "-wal"}) {
    std::error_code ec;
    const auto n = std::filesystem::file_size(s.path + suffix, ec);
    if (!ec) t.file_bytes += std::size_t(n);
  }
  Stmt b(s.db, "SELECT coalesce(sum(length(data)), 0), coalesce(sum(points), 0) FROM base_clouds", s.path);
  b.Step();
  t.base_bytes = std::size_t(b.Int(0));
  t.base_points = std::size_t(b.Int(1));
  Stmt d(s.db, "SELECT coalesce(sum(length(data)), 0), coalesce(sum(added + removed + info), 0) FROM deltas", s.path);
  d.Step();
  t.delta_bytes = std::size_t(d.Int(0));
  t.delta_points = std::size_t(d.Int(1));
  if (s.HasStepRecords()) {
    Stmt r(s.db, "SELECT count(*), coalesce(sum(length(data)), 0) FROM step_records", s.path);
    r.Step();
    t.record_steps = std::size_t(r.Int(0));
    t.record_bytes = std::size_t(r.Int(1));
  }
  return t;
}

PointCloud Store::KeyframeCloud(int keyframe_id, int session) const {
  const Impl& s = *impl_;
  const auto blobs = s.LoadBlobs(session, session, -1, {keyframe_id, keyframe_id + 1});
  if (blobs.empty()) return {};
  return detail::Dequantize(s.Rollback(blobs[0]), s.cfg.resolution_m, s.cfg.intensity_step);
}

void Store::StreamMapAt(int session, const Region& region, const PartSink& sink) const {
  const Impl& s = *impl_;
  if (session < 0 || session > s.Latest())
    throw Error(s.path + ": no session " + std::to_string(session) + " in the map store");
  s.StreamParts(session, session, [&](const Impl::KfBlobs& b) {
    return ToWorld(s.Rollback(b), b.rec.T_world_sensor, s.cfg.resolution_m, s.cfg.intensity_step, region);
  }, sink);
}

PointCloud Store::MapAt(int session, const Region& region) const {
  std::vector<PointCloud> parts;
  StreamMapAt(session, region, [&](PointCloud&& p) { parts.push_back(std::move(p)); });
  return Concat(parts, region, impl_->threads);
}

namespace {
// One keyframe's (points of a's state with no point of b's near, the reverse) in the world frame;
// false when the keyframe is the same in both states. Its deltas above `lo` are loaded, newest first.
bool KeyframeChange(const Store::Impl& s, const Store::Impl::KfBlobs& kb, int a, int lo, int hi, const Region& region,
                    std::pair<PointCloud, PointCloud>* out) {
  const bool created_between = kb.rec.session > lo;
  const bool delta_between = std::any_of(kb.deltas.begin(), kb.deltas.end(), [&](const auto& d) { return d.first <= hi; });
  if (!created_between && !delta_between) return false;
  const std::string what = "keyframe " + std::to_string(kb.rec.id);
  QCloud state = s.Decode(kb.base, what + " base");
  QCloud at_hi;
  bool passed_hi = false;
  for (const auto& [session, blob] : kb.deltas) {  // newest first: roll back to hi, then to lo
    if (!passed_hi && session <= hi) {
      at_hi = state;
      passed_hi = true;
    }
    state = detail::ApplyInverse(state, s.Decode(blob, what + " delta " + std::to_string(session)));
  }
  if (!passed_hi) at_hi = state;
  const QCloud at_lo = created_between ? QCloud() : state;
  auto world = [&](const QCloud& q) {
    return ToWorld(q, kb.rec.T_world_sensor, s.cfg.resolution_m, s.cfg.intensity_step, region);
  };
  const QCloud& at_a = a == lo ? at_lo : at_hi;
  const QCloud& at_b = a == lo ? at_hi : at_lo;
  *out = {world(detail::Unmatched(at_a, at_b)), world(detail::Unmatched(at_b, at_a))};
  return true;
}
}  // namespace

std::vector<std::pair<PointCloud, PointCloud>> Store::KeyframeChanges(int a, int b, const Region& region) const {
  const Impl& s = *impl_;
  const int lo = std::min(a, b), hi = std::max(a, b);
  if (lo < 0 || hi > s.Latest())
    throw Error(s.path + ": no session " + std::to_string(lo < 0 ? lo : hi) + " in the map store");
  std::vector<std::pair<PointCloud, PointCloud>> kept;
  s.ForEachBatch(hi, lo, [&](const std::vector<Impl::KfBlobs>& blobs) {  // the `hi` state, deltas above `lo`
    std::vector<std::pair<PointCloud, PointCloud>> out(blobs.size());
    std::vector<char> changed(blobs.size(), 0);
    ParallelFor(blobs.size(), s.threads,
                [&](std::size_t k) { changed[k] = KeyframeChange(s, blobs[k], a, lo, hi, region, &out[k]) ? 1 : 0; });
    for (std::size_t k = 0; k < out.size(); ++k)
      if (changed[k]) kept.push_back(std::move(out[k]));
  });
  return kept;
}

PointCloud Store::Live(const Region& region) const {
  const int latest = LatestSession();
  if (latest < 0) throw Error(impl_->path + ": the map store is empty");
  return MapAt(latest, region);
}

void Store::StreamLive(const Region& region, const PartSink& sink) const {
  const int latest = LatestSession();
  if (latest < 0) throw Error(impl_->path + ": the map store is empty");
  StreamMapAt(latest, region, sink);
}

void Store::StreamMeta(const Region& region, const PartSink& sink) const {
  const Impl& s = *impl_;
  const int latest = s.Latest();
  if (latest < 0) throw Error(s.path + ": the map store is empty");
  const double carve_units = s.cfg.meta_carve_radius_m / s.cfg.resolution_m;
  s.StreamParts(latest, -1, [&](const Impl::KfBlobs& b) {  // every delta, newest first
    const std::string what = "keyframe " + std::to_string(b.rec.id);
    std::vector<QCloud> deltas;
    for (const auto& [session, blob] : b.deltas) deltas.push_back(s.Decode(blob, what + " delta"));
    QCloud state = s.Decode(b.base, what + " base");
    for (const QCloud& d : deltas) state = detail::ApplyInverse(state, d);  // first state of the keyframe
    // Weak PD (a new keyframe's parked cars) never enters the meta map.
    state.erase(std::remove_if(state.begin(), state.end(),
                               [](const QPoint& p) { return p.cls == std::uint8_t(PointClass::kPDWeak); }),
                state.end());
    QCloud carve;
    for (auto it = deltas.rbegin(); it != deltas.rend(); ++it) {  // oldest step first
      const int step = b.deltas[std::size_t(deltas.rend() - it - 1)].first;
      for (const QPoint& p : *it) {
        if (p.role == detail::kAdded && p.session == step && p.cls == std::uint8_t(PointClass::kPDStrong))
          state.push_back(p);
        if (p.role == detail::kRemovedChange) carve.push_back(p);
      }
    }
    if (!carve.empty()) {
      const std::vector<bool> cut = detail::WithinRadiusQ(state, carve, carve_units);
      QCloud kept;
      kept.reserve(state.size());
      for (std::size_t i = 0; i < state.size(); ++i)
        if (!cut[i]) kept.push_back(state[i]);
      state.swap(kept);
    }
    return ToWorld(state, b.rec.T_world_sensor, s.cfg.resolution_m, s.cfg.intensity_step, region);
  }, sink);
}

PointCloud Store::Meta(const Region& region) const {
  std::vector<PointCloud> parts;
  StreamMeta(region, [&](PointCloud&& p) { parts.push_back(std::move(p)); });
  return Concat(parts, region, impl_->threads);
}

PointCloud Store::StepChanges(int session, const Region& region) const {
  const Impl& s = *impl_;
  if (session < 1 || session > s.Latest())
    throw Error(s.path + ": no session step " + std::to_string(session) + " in the map store");
  const auto blobs = s.LoadBlobs(session, -1, session);
  std::vector<PointCloud> parts(blobs.size());
  ParallelFor(blobs.size(), s.threads, [&](std::size_t k) {
    QCloud changes;
    for (const auto& [step, blob] : blobs[k].deltas) {
      for (QPoint p : s.Decode(blob, "keyframe " + std::to_string(blobs[k].rec.id) + " delta")) {
        if (p.role == detail::kAdded && p.session == step &&
            (p.cls == std::uint8_t(PointClass::kPDStrong) || p.cls == std::uint8_t(PointClass::kPDWeak))) {
        } else if (p.role == detail::kRemovedChange) {
          p.cls = std::uint8_t(PointClass::kNDStrong);
        } else if (p.role == detail::kInfoNDWeak) {
          p.cls = std::uint8_t(PointClass::kNDWeak);
        } else {
          continue;
        }
        p.session = std::uint16_t(step);
        changes.push_back(p);
      }
    }
    parts[k] = ToWorld(changes, blobs[k].rec.T_world_sensor, s.cfg.resolution_m, s.cfg.intensity_step, region);
  });
  // Keyframes this step created (new territory) hold their changes in the base cloud: their
  // weak PD (space the reference saw free, e.g. a new object) is a change of the step too.
  // Only their ids' range is loaded, a batch at a time (never every keyframe's base).
  Stmt range(s.db, "SELECT min(id), max(id) FROM keyframes WHERE session = ?", s.path);
  range.Bind(1, session);
  if (range.Step() && !range.Null(0))
    s.ForEachBatch(session, session, [&](const std::vector<Impl::KfBlobs>& blobs) {
      std::vector<PointCloud> fresh(blobs.size());
      ParallelFor(blobs.size(), s.threads, [&](std::size_t k) {
        if (blobs[k].rec.session != session) return;
        QCloud changes;
        for (const QPoint& p : s.Rollback(blobs[k]))
          if (p.session == session && p.cls == std::uint8_t(PointClass::kPDWeak)) changes.push_back(p);
        fresh[k] = ToWorld(changes, blobs[k].rec.T_world_sensor, s.cfg.resolution_m, s.cfg.intensity_step, region);
      });
      for (auto& f : fresh)
        if (!f.empty()) parts.push_back(std::move(f));
    }, {int(range.Int(0)), int(range.Int(1)) + 1});
  Region no_voxel = region;
  no_voxel.voxel_m = 0;
  return Concat(parts, no_voxel, s.threads);
}

// ===================================================================================== fsck
namespace {
// Collects an fsck's findings (the first 200 problems are listed).
struct FsckFindings {
  FsckReport r;
  void Problem(const std::string& p) {
    r.ok = false;
    if (r.problems.size() < 200) r.problems.push_back(p);
  }
};

void CheckDatabase(const Store::Impl& s, FsckFindings& f) {
  try {
    const std::string v = s.Info("schema_version");
    if (!ReadableSchema(v)) f.Problem("schema version " + v);
  } catch (const Error& e) {
    f.Problem(e.what());
  }
  Stmt integrity(s.db, "PRAGMA integrity_check", s.path);
  while (integrity.Step())
    if (integrity.Text(0) != "ok") f.Problem("integrity_check: " + integrity.Text(0));
  Stmt keys(s.db, "PRAGMA foreign_key_check", s.path);
  while (keys.Step()) f.Problem("foreign key violation in table " + keys.Text(0) + " row " + std::to_string(keys.Int(1)));
}

void CheckSessions(const std::vector<SessionRecord>& sessions, FsckFindings& f) {
  for (std::size_t k = 0; k < sessions.size(); ++k) {
    const auto& ss = sessions[k];
    if (ss.order != int(k)) f.Problem("session orders are not 0..N-1 (found " + std::to_string(ss.order) + ")");
    if (k == 0 && ss.reference != -1) f.Problem("central session has a reference");
    if (k > 0 && (ss.reference < 0 || ss.reference >= ss.order))
      f.Problem("session " + ss.name + " references session " + std::to_string(ss.reference));
  }
}

// Decodes a blob (checksum, sizes) and counts it; the decoded points, or none on a problem.
std::optional<QCloud> CheckBlob(const Store::Impl& s, const std::string& blob, const std::string& where, FsckFindings& f) {
  ++f.r.blobs;
  f.r.bytes += blob.size();
  try {
    QCloud q = s.Decode(blob, where);
    f.r.points += q.size();
    return q;
  } catch (const Error& e) {
    f.Problem(e.what());
    return std::nullopt;
  }
}

// Every delta: its keyframe and step exist, its blob decodes, its role counts match the row.
// Returns per keyframe the newest step whose delta changed points.
std::map<int, int> CheckDeltas(const Store::Impl& s, const std::map<int, KeyframeRecord>& kfs, int latest,
                               FsckFindings& f) {
  std::map<int, int> last_change;
  Stmt st(s.db, "SELECT keyframe, session, added, removed, info, data FROM deltas", s.path);
  while (st.Step()) {
    const int kf = int(st.Int(0)), ses = int(st.Int(1));
    const std::string where = "delta (keyframe " + std::to_string(kf) + ", session " + std::to_string(ses) + ")";
    const auto it = kfs.find(kf);
    if (it == kfs.end()) f.Problem(where + ": no such keyframe");
    else if (ses <= it->second.session) f.Problem(where + ": not after the keyframe's creation");
    if (ses < 1 || ses > latest) f.Problem(where + ": no such session step");
    if (const auto q = CheckBlob(s, st.Blob(5), where, f)) {
      std::size_t a = 0, rm = 0, inf = 0;
      for (const QPoint& p : *q) (p.role == detail::kAdded ? a : p.role == detail::kInfoNDWeak ? inf : rm)++;
      if (a != std::size_t(st.Int(2)) || rm != std::size_t(st.Int(3)) || inf != std::size_t(st.Int(4)))
        f.Problem(where + ": point counts differ from the row");
    }
    if (st.Int(2) + st.Int(3) > 0) last_change[kf] = std::max(last_change[kf], ses);
  }
  return last_change;
}

// Every base cloud: its keyframe exists, it is as of the keyframe's newest changing delta, its
// blob decodes to the row's point count; every keyframe has one and an owning session.
void CheckBases(const Store::Impl& s, const std::map<int, KeyframeRecord>& kfs, int latest,
                const std::map<int, int>& last_change, FsckFindings& f) {
  std::set<int> has_base;
  Stmt st(s.db, "SELECT keyframe, as_of, points, data FROM base_clouds", s.path);
  while (st.Step()) {
    const int kf = int(st.Int(0)), as_of = int(st.Int(1));
    const std::string where = "base cloud of keyframe " + std::to_string(kf);
    has_base.insert(kf);
    const auto it = kfs.find(kf);
    if (it == kfs.end()) f.Problem(where + ": no such keyframe");
    else if (as_of < it->second.session || as_of > latest) f.Problem(where + ": as_of out of range");
    const auto lc = last_change.find(kf);
    if (lc != last_change.end() && lc->second != as_of) f.Problem(where + ": not as of its newest delta");
    if (const auto q = CheckBlob(s, st.Blob(3), where, f))
      if (q->size() != std::size_t(st.Int(2))) f.Problem(where + ": point count differs from the row");
  }
  for (const auto& [id, k] : kfs) {
    if (!has_base.count(id)) f.Problem("keyframe " + std::to_string(id) + " has no base cloud");
    if (k.session < 0 || k.session > latest) f.Problem("keyframe " + std::to_string(id) + " owned by no session");
  }
}
}  // namespace

bool Store::Impl::HasTable(const std::string& name) const {
  Stmt st(db, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", path);
  st.Bind(1, name);
  return st.Step();
}

bool Store::Impl::HasStepRecords() const { return HasTable("step_records"); }

std::vector<Pose> Store::Trajectory(int order) const {
  const Impl& s = *impl_;
  std::vector<Pose> out;
  if (!s.HasTable("trajectories")) return out;
  Stmt st(s.db, "SELECT pose FROM trajectories WHERE session = ? ORDER BY idx", s.path);
  st.Bind(1, order);
  while (st.Step()) out.push_back(PoseFromText(st.Text(0), s.path + ": trajectory of session " + std::to_string(order)));
  return out;
}

std::string Store::StepRecord(int session, const std::string& key) const {
  const Impl& s = *impl_;
  if (!HasStepRecord(session, key)) return {};
  Stmt st(s.db, "SELECT data FROM step_records WHERE session = ?", s.path);
  st.Bind(1, session);
  st.Step();
  const std::string data = st.Blob(0);
  return detail::UnpackBytes(data.data(), data.size(),
                             s.path + ": step record of session " + std::to_string(session));
}

bool Store::HasStepRecord(int session, const std::string& key) const {
  const Impl& s = *impl_;
  if (!s.HasStepRecords()) return false;
  Stmt st(s.db, "SELECT key FROM step_records WHERE session = ?", s.path);
  st.Bind(1, session);
  return st.Step() && st.Text(0) == key;
}

void Store::PutStepRecord(int session, const std::string& key, const std::string& raw) {
  Impl& s = *impl_;
  if (s.read_only) throw Error(s.path + ": opened read-only: cannot write a step record");
  Transaction tx(s);
  Stmt st(s.db, "INSERT OR REPLACE INTO step_records(session, key, data) VALUES(?, ?, ?)", s.path);
  st.Bind(1, session).Bind(2, key).BindBlob(3, detail::PackBytes(raw, s.cfg.zstd_level)).Run();
  tx.Commit();
}

namespace {
void CheckStepRecords(const Store::Impl& s, int latest, FsckFindings& f) {
  if (!s.HasStepRecords()) return;
  Stmt st(s.db, "SELECT session, data FROM step_records", s.path);
  while (st.Step()) {
    const std::string where = "step record of session " + std::to_string(st.Int(0));
    if (st.Int(0) < 1 || st.Int(0) > latest) f.Problem(where + ": no such session step");
    const std::string data = st.Blob(1);
    try {
      std::vector<MapObject> kept, rejected;
      detail::DecodeObjects(detail::UnpackBytes(data.data(), data.size(), where), where, &kept, &rejected);
    } catch (const Error& e) {
      f.Problem(e.what());
    }
  }
}
}  // namespace

FsckReport Store::Fsck() const {
  const Impl& s = *impl_;
  FsckFindings f;
  CheckDatabase(s, f);
  const auto sessions = Sessions();
  f.r.sessions = sessions.size();
  CheckSessions(sessions, f);
  const int latest = int(sessions.size()) - 1;
  std::map<int, KeyframeRecord> kfs;
  try {
    for (const auto& k : s.Keyframes()) kfs[k.id] = k;
  } catch (const Error& e) {
    f.Problem(e.what());
  }
  f.r.keyframes = kfs.size();
  const std::map<int, int> last_change = CheckDeltas(s, kfs, latest, f);
  CheckBases(s, kfs, latest, last_change, f);
  CheckStepRecords(s, latest, f);
  return f.r;
}

std::uint64_t Store::Digest() const {
  const Impl& s = *impl_;
  std::uint64_t h = detail::Fnv1a64("ltmap", 5);
  auto add = [&](const std::string& v) {
    const std::uint64_t n = v.size();
    h = detail::Fnv1a64(&n, sizeof(n), h);
    h = detail::Fnv1a64(v.data(), v.size(), h);
  };
  const char* queries[] = {
      "SELECT id, name, coalesce(reference, -1), anchor, params, keyframes_new, keyframes_changed, pd_strong, pd_weak, "
      "nd_strong, nd_weak, superseded, restored, points, bytes FROM sessions ORDER BY id",
      "SELECT id, session, source_index, pose FROM keyframes ORDER BY id",
      "SELECT keyframe, as_of, points, data FROM base_clouds ORDER BY keyframe",
      "SELECT keyframe, session, added, removed, info, data FROM deltas ORDER BY keyframe, session"};
  std::vector<std::string> all(std::begin(queries), std::end(queries));
  if (s.HasTable("trajectories")) all.push_back("SELECT session, idx, pose FROM trajectories ORDER BY session, idx");
  for (const std::string& q : all) {
    Stmt st(s.db, q, s.path);
    while (st.Step()) {
      for (int c = 0; c < st.Columns(); ++c) add(st.Blob(c));
      add("|");
    }
    add("#");
  }
  return h;
}

}  // namespace ltm::map
