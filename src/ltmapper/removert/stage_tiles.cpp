// The LT-removert stage tile by tile from files (tiles.stage; RunRemovertStage): every session's
// HD tiles and every pair's LD tiles run as the `ltmapper tiles` jobs do, under OUT/.tiles (removed
// at the end), merged into the stage's folders; a pair's keyframe folders are cut from the merged
// clouds by an external bucket sort (KeyframeSpill). Memory: a tile job, the merges' pieces and the
// spill's buffer, not the sessions' maps. The files equal the whole stage's, except the whole-map
// PLY twins (map.ply, changes.ply: they would hold the whole maps), which are not written.
#include "ltmapper/removert/detail.hpp"
#include "ltmapper/removert/tile_files.hpp"

#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>

namespace ltm::removert::detail {
namespace {

namespace fs = std::filesystem;

// Points held by the keyframe spill before they are appended to the buckets' files (16 B each).
constexpr std::size_t kSpillPoints = std::size_t(1) << 20;

// A pair's keyframe clouds by bucket (KeyframeOwners), appended as raw points to one file per
// (bucket, cloud) under `dir`; each bucket's points keep the order they came in.
class KeyframeSpill {
 public:
  KeyframeSpill(std::string dir, std::size_t buckets, bool keep)
      : dir_(std::move(dir)), keep_(keep), pending_(buckets), counts_(buckets) {
    if (keep_) io::MakeDirs(dir_);
  }
  void Add(int cloud, const PointCloud& pts, const std::vector<std::uint32_t>& owner) {
    for (std::size_t i = 0; i < pts.size(); ++i) {
      ++counts_[owner[i]][std::size_t(cloud)];
      if (!keep_) continue;
      pending_[owner[i]][std::size_t(cloud)].push_back(pts.points[i]);
      if (++pending_points_ == kSpillPoints) Flush();
    }
  }
  void Flush() {
    for (std::size_t b = 0; b < pending_.size(); ++b)
      for (int c = 0; c < kKeyframeClouds; ++c) {
        std::vector<PointXYZI>& p = pending_[b][std::size_t(c)];
        if (p.empty()) continue;
        std::ofstream out(File(b, c), std::ios::binary | std::ios::app);
        out.write(reinterpret_cast<const char*>(p.data()), std::streamsize(p.size() * sizeof(PointXYZI)));
        if (!out) throw Error(File(b, c), 0, "cannot append (disk full?)");
        p.clear();
        p.shrink_to_fit();
      }
    pending_points_ = 0;
  }
  PointCloud Read(std::size_t bucket, int cloud) const {
    PointCloud c;
    c.points.resize(counts_[bucket][std::size_t(cloud)]);
    if (c.empty()) return c;
    std::ifstream in(File(bucket, cloud), std::ios::binary);
    in.read(reinterpret_cast<char*>(c.points.data()), std::streamsize(c.size() * sizeof(PointXYZI)));
    if (!in) throw Error(File(bucket, cloud), 0, "shorter than the points spilled into it");
    return c;
  }
  const std::vector<std::array<std::size_t, kKeyframeClouds>>& Counts() const { return counts_; }

 private:
  std::string File(std::size_t bucket, int cloud) const {
    return dir_ + "/" + std::to_string(bucket) + "_" + kKeyframeCloudNames[cloud] + ".bin";
  }
  std::string dir_;
  bool keep_;  // spill the points (keyframe folders written), else only count them
  std::vector<std::array<std::vector<PointXYZI>, kKeyframeClouds>> pending_;
  std::vector<std::array<std::size_t, kKeyframeClouds>> counts_;
  std::size_t pending_points_ = 0;
};

// The files each keyframe cloud is cut from, in order (the whole stage's concatenations).
std::vector<std::string> SourcesOf(int cloud, const std::string& central_dir, const std::string& pair_dir) {
  std::vector<std::string> files;
  if (cloud == kKfStatic) files.push_back(io::layout::StaticMapIn(central_dir));
  if (cloud == kKfHd) files.push_back(io::layout::HdMapIn(central_dir));
  for (auto m : KeyframeCloudLd(cloud)) files.push_back(pair_dir + "/" + LdCloudFile(m));
  return files;
}

// The pair's keyframe folders and keyframes.csv from its merged clouds (pair_dir) and the central's
// maps (central_dir); returns the new keyframes' indices.
std::vector<int> WritePairKeyframes(const std::string& pair_dir, const std::string& central_dir,
                                    const std::vector<WorldKeyframe>& ckf, const std::vector<WorldKeyframe>& qkf, int ci,
                                    int qi, const RemovertConfig& cfg, int threads) {
  const KeyframeOwners owners(ckf, qkf, cfg, threads);
  KeyframeSpill spill(pair_dir + "/.spill", ckf.size() + qkf.size(), cfg.write_keyframes);
  PointCloud piece;
  for (int c = 0; c < kKeyframeClouds; ++c)
    for (const std::string& file : SourcesOf(c, central_dir, pair_dir)) {
      io::PcdPieceReader reader(file);
      while (reader.Next(kReadPiece, &piece))
        spill.Add(c, piece, c == kKfPdStrong || c == kKfPdWeak ? owners.Pd(piece) : owners.Central(piece));
    }
  spill.Flush();
  const auto& counts = spill.Counts();
  std::vector<bool> owns_pd(counts.size());
  for (std::size_t b = 0; b < counts.size(); ++b) owns_pd[b] = counts[b][kKfPdStrong] + counts[b][kKfPdWeak] > 0;
  const std::vector<int> new_list = owners.NewKeyframes(owns_pd);
  if (cfg.write_keyframes) {
    ParallelFor(ckf.size(), threads, [&](std::size_t k) {
      std::array<PointCloud, kKeyframeClouds> clouds;
      for (int c = 0; c < kKeyframeClouds; ++c) clouds[std::size_t(c)] = spill.Read(k, c);
      WriteKeyframeDir(pair_dir + "/keyframes/" + io::layout::KeyframeDirName(ckf[k].index), ckf[k].T_world_sensor,
                       CentralKeyframeParts(std::move(clouds), ci, qi), cfg);
    });
    ParallelFor(new_list.size(), threads, [&](std::size_t t) {
      const std::size_t j = std::size_t(new_list[t]), b = ckf.size() + j;
      WriteKeyframeDir(pair_dir + "/new_keyframes/" + io::layout::KeyframeDirName(qkf[j].index), qkf[j].T_world_sensor,
                       NewKeyframeParts(spill.Read(b, kKfPdStrong), spill.Read(b, kKfPdWeak), qi), cfg);
    });
  }
  fs::remove_all(pair_dir + "/.spill");
  WriteKeyframesCsv(pair_dir, ckf, qkf, ci, qi, counts, new_list);
  std::vector<int> new_idx;
  for (int j : new_list) new_idx.push_back(qkf[std::size_t(j)].index);
  return new_idx;
}

// The named files of `from` moved into `to` (made).
void MoveFiles(const std::string& from, const std::string& to, const std::vector<std::string>& names) {
  io::MakeDirs(to);
  for (const std::string& n : names) fs::rename(from + "/" + n, to + "/" + n);
}

}  // namespace

void RunStageFromTiles(const RemovertConfig& cfg, const std::vector<std::string>& session_dirs,
                       const std::vector<std::string>& poses_files, const std::vector<std::string>& names,
                       const std::vector<std::vector<WorldKeyframe>>& kfs, const std::string& out, int threads,
                       StageReport* rep) {
  if (cfg.write_ply) spdlog::info("removert: tile by tile, the whole-map PLY twins (map.ply, changes.ply) are not written");
  const std::string work = out + "/.tiles";
  auto hd_plan = [&](std::size_t s) { return work + "/hd_" + std::to_string(s); };
  for (std::size_t s = 0; s < session_dirs.size(); ++s) {
    spdlog::info("removert: HD removal of {} ({} keyframes), tile by tile from files", names[s], kfs[s].size());
    // The session's plan carries the LD tolerance of the pair it is the query of (ForPair; a
    // session is the query of one pair at most): its pairs' LD plans read it there.
    std::size_t central = s;
    for (const auto& [c, q] : rep->pairs)
      if (std::size_t(q) == s) central = std::size_t(c);
    WriteTilePlan(hd_plan(s), session_dirs[s], poses_files[s], cfg.ForPair(central, s), threads, session_dirs[0]);
    RunTileJobs(hd_plan(s), {}, threads);
    rep->hd.push_back(MergeTileJobs(hd_plan(s), hd_plan(s) + "_out"));
    MoveFiles(hd_plan(s) + "_out", io::layout::SessionChangesDir(out, names[s]),
              {fs::path(io::layout::StaticMapIn(".")).filename().string(),
               fs::path(io::layout::HdMapIn(".")).filename().string()});
    for (const auto& [c, q] : rep->pairs) {
      if (std::size_t(q) != s) continue;
      const std::string pair_dir = out + "/" + io::layout::PairDirName(c, q), ld_plan = work + "/" + io::layout::PairDirName(c, q);
      spdlog::info("removert: LD {} vs {}, tile by tile from files", names[std::size_t(c)], names[s]);
      WriteLdTilePlan(ld_plan, hd_plan(std::size_t(c)), hd_plan(s));
      RunLdTileJobs(ld_plan, {}, threads);
      rep->ld.push_back(MergeLdTileJobs(ld_plan, ld_plan + "_out"));
      MoveFiles(ld_plan + "_out", pair_dir, LdPairCloudFiles());
      rep->new_keyframes.push_back(WritePairKeyframes(pair_dir, io::layout::SessionChangesDir(out, names[std::size_t(c)]),
                                                      kfs[std::size_t(c)], kfs[s], c, q, cfg, threads));
    }
  }
  fs::remove_all(work);
}

}  // namespace ltm::removert::detail
