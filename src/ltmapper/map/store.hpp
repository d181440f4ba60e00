// ltmapper map: the Store, one SQLite file NAME.ltmap (schema and rules: README.md here).
#pragma once

#include "ltmapper/map/config.hpp"
#include "ltmapper/map/records.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace ltm::map {

class Store {
 public:
  // Creates a new store file (error when `path` exists). Encoding values come from `cfg`.
  // kUnpublished: a file no one reads until the caller renames it into place (map init's
  // temporary): written without a journal, each page once; Close() makes it durable. A crash
  // leaves a broken temporary, never a broken store.
  enum class Creation { kPublished, kUnpublished };
  static Store Create(const std::string& path, const MapConfig& cfg, Creation creation = Creation::kPublished);
  // Closes the store (nothing else may be called after): an unpublished one is synced to disk and
  // in rollback-journal mode after; errors are thrown. The destructor closes too, quietly.
  void Close();
  // kReadOnly: SQLITE_OPEN_READONLY, no journal mode switch, nothing written or created (works on
  // read-only media and on another user's store); integrating through such a store fails.
  enum class Access { kReadWrite, kReadOnly };
  // Opens an existing store; checks the schema version. Integration parameters come from `cfg`,
  // the encoding (resolution, intensity step) from the store.
  static Store Open(const std::string& path, const MapConfig& cfg = {}, Access access = Access::kReadWrite);
  Store(Store&&) noexcept;
  Store& operator=(Store&&) noexcept;
  ~Store();

  const std::string& path() const;
  const MapConfig& config() const;  // encoding fields as stored
  void set_threads(int threads);    // 0 = all cores
  int threads() const;

  // The central session: every keyframe becomes a map keyframe. One transaction.
  IntegrationResult IntegrateBase(const SessionMeta& session, const std::vector<KeyframeInput>& keyframes);
  // The same, each keyframe's cloud read when its chunk is encoded.
  IntegrationResult IntegrateBaseFrom(const SessionMeta& session, const KeyframeSource& keyframes);
  // A query session's changes against `reference` (an integrated session, usually the central
  // one): per reference keyframe with a delta, the keyframe's state becomes reference-state − ND
  // + PD. `query_keyframes` carry this session's points that no reference keyframe owns (LT-
  // removert's new_keyframes/: PD in new territory; cls array optional, default kPDStrong): one
  // with no map keyframe within new_keyframe_radius_m becomes a new map keyframe (its cloud is the
  // base); otherwise its points join the nearest map keyframe's target (a keyframe created by an
  // earlier query is replaced by what this session saw there). Keyframes without any input keep
  // their latest state. One transaction (BEGIN IMMEDIATE ... COMMIT): an exception or a kill
  // leaves the previous state.
  IntegrationResult IntegrateSession(const SessionMeta& session, const std::string& reference,
                                     const std::vector<KeyframeDelta>& deltas,
                                     const std::vector<KeyframeInput>& query_keyframes);
  // The same, each delta and query cloud read when the chunk of map keyframes it goes to is
  // stepped (a query keyframe's cloud is "empty" when its slot's `points` is 0).
  IntegrationResult IntegrateSessionFrom(const SessionMeta& session, const std::string& reference,
                                         const DeltaSource& deltas, const KeyframeSource& query_keyframes);
  // Test hook: called inside the integration transaction after each keyframe is written.
  std::function<void(std::size_t keyframes_written)> on_keyframe_written;

  std::vector<SessionRecord> Sessions() const;
  // Session `order`'s trajectory (SessionMeta::trajectory), empty when the store has none for it
  // (written before schema 4, or given none).
  std::vector<Pose> Trajectory(int order) const;
  std::vector<KeyframeRecord> Keyframes() const;
  int SessionOrder(const std::string& name) const;  // throws when unknown
  int LatestSession() const;                        // -1 when empty
  StoreTotals Totals() const;

  // One keyframe as of `session` (local frame; cls and session arrays set); empty when the
  // keyframe did not exist yet.
  PointCloud KeyframeCloud(int keyframe_id, int session) const;
  // The map as of `session` in the world frame (restore by chained inverse deltas).
  PointCloud MapAt(int session, const Region& region = {}) const;
  PointCloud Live(const Region& region = {}) const;  // latest state, all PD
  // The same maps part by part: sink(part) for each keyframe's part in keyframe order, region box
  // applied, its voxel not (a voxel spans keyframes: WriteLabelledCloudParts applies it by tiles).
  // Memory is a batch of keyframes, not the map.
  void StreamMapAt(int session, const Region& region, const PartSink& sink) const;
  void StreamLive(const Region& region, const PartSink& sink) const;
  void StreamMeta(const Region& region, const PartSink& sink) const;
  // What differs between the states as of sessions `a` and `b`, per keyframe with a delta between
  // them (or created between them): (points of a's state with no point of b's within one grid
  // step, the reverse), world frame. Every other keyframe is the same in both and is neither
  // decoded nor returned (map::Diff).
  std::vector<std::pair<PointCloud, PointCloud>> KeyframeChanges(int a, int b, const Region& region = {}) const;
  // Meta map: the first state of every keyframe plus strong PD of every later step, minus
  // everything within meta_carve_radius_m of any point a step removed as seen-through (strong ND).
  PointCloud Meta(const Region& region = {}) const;
  // The changes of one step in the world frame: PD strong/weak (added), ND strong (removed),
  // ND weak (kept), plus the weak PD of the keyframes the step created (new territory).
  // cls set, session = the step.
  PointCloud StepChanges(int session, const Region& region = {}) const;
  // Objects a user can act on (objects.cpp): Euclidean clusters (PCL) of each step's strong ND
  // and PD above the local ground, kept only in space both sessions observed and when they pass
  // the geometric rules; moved pairs linked. `rejected` (optional) receives the other clusters
  // with the reason.
  // Each step's objects are kept in the store once computed (CacheObjects) and decoded from there
  // while the object config and the code (CodeId) are the same; a step without them is computed
  // (two map restores).
  // `rejected` rows carry no clouds.
  std::vector<MapObject> Objects(std::vector<MapObject>* rejected = nullptr) const;  // needs object_sensor_step_deg > 0
  // Computes and stores the objects of every step that has none for this object config (one
  // transaction each): after it, Objects() costs the decoding, not the map restores of every step.
  // Returns how many steps were computed.
  std::size_t CacheObjects();
  // Derived per-step records (the object cache): the record of step `session` made with `key`,
  // empty when there is none or it was made with another key.
  std::string StepRecord(int session, const std::string& key) const;
  bool HasStepRecord(int session, const std::string& key) const;  // without reading the record
  void PutStepRecord(int session, const std::string& key, const std::string& raw);

  // Schema version, PRAGMA integrity_check, foreign keys, every blob's checksum and decoding,
  // references between rows, and that every stored base equals its deltas' composition counts.
  FsckReport Fsck() const;
  // Hash of all logical content (sessions, trajectories, keyframes, blobs); equal stores give equal digests.
  std::uint64_t Digest() const;

  struct Impl;  // opaque (SQLite handle); public only so store.cpp helpers can name it

 private:
  explicit Store(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace ltm::map
