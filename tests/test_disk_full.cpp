// Disk-full trials (issue 21): commands that write -- `map init` / `map integrate` into a store, a
// PCD export, a stage output folder (LT-removert) -- on a file system too small for what they
// write. Each must end in an error naming the file with the previous content intact (the store
// opens, passes fsck and holds its previous state -- or, when COMMIT went into the -wal and only
// the checkpoint failed, the next state with an error that says to keep the -wal; nothing partial
// under a final name), or in success with a complete, self-contained result (the store file alone
// holds the integration). Never a crash, never a success with data only in -wal.
//
// Two ways to run out of space: a file-size limit on the command (setrlimit(RLIMIT_FSIZE) in the
// child with SIGXFSZ ignored, so a write past it fails with EFBIG as on a full disk), which runs
// anywhere; and a small tmpfs mounted for the test and filled up to a few bytes (ENOSPC), which
// needs the right to mount (root with CAP_SYS_ADMIN): skipped with a message elsewhere.
#include "ltmapper/io/io.hpp"
#include "ltmapper/map/map.hpp"

#include "test_map_layout.hpp"
#include "test_removert_scene.hpp"
#include "test_util.hpp"

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/statvfs.h>
#include <sys/wait.h>
#include <unistd.h>

namespace ltm {
namespace {

namespace fs = std::filesystem;
using test::DigestOf;

struct Result {
  int rc = -1;  // exit status; 128 + signal when killed by one
  std::string out;
};

// Runs ltmapper with `args`; with `fsize_limit` >= 0 under that RLIMIT_FSIZE, SIGXFSZ ignored.
Result RunLtm(const std::vector<std::string>& args, long long fsize_limit) {
  int fd[2];
  if (::pipe(fd) != 0) throw Error(std::string("pipe: ") + std::strerror(errno));
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(fd[1], 1);
    ::dup2(fd[1], 2);
    ::close(fd[0]);
    ::close(fd[1]);
    if (fsize_limit >= 0) {
      const rlimit lim{rlim_t(fsize_limit), rlim_t(fsize_limit)};
      if (::setrlimit(RLIMIT_FSIZE, &lim) != 0) _exit(126);
      ::signal(SIGXFSZ, SIG_IGN);  // kept across exec: writes fail with EFBIG instead
    }
    std::vector<char*> argv{const_cast<char*>(LTM_EXE)};
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(LTM_EXE, argv.data());
    _exit(127);
  }
  ::close(fd[1]);
  Result r;
  char buf[4096];
  for (ssize_t n; (n = ::read(fd[0], buf, sizeof(buf))) != 0;) {
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) break;
    r.out.append(buf, std::size_t(n));
  }
  ::close(fd[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

// A tmpfs of `bytes` mounted on `dir` for the test's lifetime; mounted() is false (reason()
// says why) where this process may not mount.
class SmallTmpfs {
 public:
  SmallTmpfs(std::string dir, std::size_t bytes) : dir_(std::move(dir)) {
    fs::create_directories(dir_);
    const std::string opt = "size=" + std::to_string(bytes) + ",mode=0700";
    if (::mount("tmpfs", dir_.c_str(), "tmpfs", MS_NOSUID | MS_NODEV, opt.c_str()) == 0)
      mounted_ = true;
    else
      reason_ = std::string("mount -t tmpfs not allowed here (") + std::strerror(errno) + ")";
  }
  ~SmallTmpfs() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
  }
  bool mounted() const { return mounted_; }
  const std::string& reason() const { return reason_; }
  const std::string& dir() const { return dir_; }
  std::size_t Free() const {
    struct statvfs s {};
    ::statvfs(dir_.c_str(), &s);
    return std::size_t(s.f_bavail) * s.f_frsize;
  }
  // Writes a filler file so that about `left` bytes stay free (rounded down to pages).
  void FillLeaving(std::size_t left) {
    const std::size_t free_now = Free();
    std::ofstream f(filler(), std::ios::binary);
    const std::string block(4096, '\0');
    for (std::size_t n = 0; n + left + block.size() <= free_now; n += block.size()) f.write(block.data(), block.size());
  }
  void Unfill() { fs::remove(filler()); }

 private:
  std::string filler() const { return dir_ + "/filler"; }
  std::string dir_, reason_;
  bool mounted_ = false;
};

// How one trial runs out of space: a file-size limit, or the tmpfs filled to leave `free` bytes.
struct Space {
  long long fsize = -1;
  SmallTmpfs* tmpfs = nullptr;
  std::size_t free = 0;
  std::string Describe() const {
    return tmpfs ? "tmpfs with " + std::to_string(free) + " bytes free" : "RLIMIT_FSIZE " + std::to_string(fsize);
  }
};

Result RunIn(const Space& space, const std::vector<std::string>& args) {
  if (space.tmpfs) space.tmpfs->FillLeaving(space.free);
  Result r = RunLtm(args, space.fsize);
  if (space.tmpfs) space.tmpfs->Unfill();
  return r;
}

std::size_t Size(const std::string& f) {
  std::error_code ec;
  const auto n = fs::file_size(f, ec);
  return ec ? 0 : std::size_t(n);
}

// Names in `dir` that contain `part` (temporaries: ".tmp-", ".old-").
std::vector<std::string> NamesWith(const std::string& dir, const std::string& part) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string n = e.path().filename().string();
    if (n.find(part) != std::string::npos) out.push_back(n);
  }
  return out;
}

// Every file below `dir` (relative path -> content).
std::map<std::string, std::string> Contents(const std::string& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out[fs::relative(e.path(), dir).string()] = test::ReadText(e.path().string());
  return out;
}

// The store's digest; a store that does not open (malformed) or fails fsck is a test failure.
std::uint64_t CheckedDigest(const std::string& copy, const std::string& what) {
  try {
    bool ok = false;
    const std::uint64_t d = DigestOf(copy, &ok);
    EXPECT_TRUE(ok) << what << " does not pass fsck";
    return d;
  } catch (const std::exception& e) {
    ADD_FAILURE() << what << " does not open: " << e.what();
    return 0;
  }
}

// The digest of the store file alone (copied without its companions), checked by fsck.
std::uint64_t DigestAlone(const std::string& store, const std::string& scratch) {
  fs::remove_all(scratch);
  fs::create_directories(scratch);
  fs::copy_file(store, scratch + "/alone.ltmap");
  return CheckedDigest(scratch + "/alone.ltmap", store + " alone");
}

// The digest of the store with its -wal (as a user who kept both has it), checked by fsck.
std::uint64_t DigestWithWal(const std::string& store, const std::string& scratch) {
  fs::remove_all(scratch);
  fs::create_directories(scratch);
  fs::copy_file(store, scratch + "/m.ltmap");
  if (fs::exists(store + "-wal")) fs::copy_file(store + "-wal", scratch + "/m.ltmap-wal");
  return CheckedDigest(scratch + "/m.ltmap", store + " with its -wal");
}

class DiskFull : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(LTM_EXE)) GTEST_SKIP() << "ltmapper executable not built";
    test::WriteLayout(tmp_.str(), 12);
    pristine_ = tmp_ / "pristine.ltmap";
    const Result init = RunLtm({"map", "init", "--quiet", "--store", pristine_, "--aligned", aligned(), "--changes",
                                changes()},
                               -1);
    ASSERT_EQ(init.rc, 0) << init.out;
    before_ = DigestAlone(pristine_, tmp_ / "scratch");
    const std::string full = tmp_ / "full/m.ltmap";
    fs::create_directories(tmp_ / "full");
    fs::copy_file(pristine_, full);
    const Result r = RunLtm(Integrate(full), -1);
    ASSERT_EQ(r.rc, 0) << r.out;
    after_ = DigestAlone(full, tmp_ / "scratch");
    ASSERT_NE(before_, after_);
    p_bytes_ = Size(pristine_);
    a_bytes_ = Size(full);
    ASSERT_GT(a_bytes_, p_bytes_);
    std::printf("store: %zu bytes before, %zu after integrating session_01\n", p_bytes_, a_bytes_);
  }

  std::string aligned() const { return tmp_ / "aligned"; }
  std::string changes() const { return tmp_ / "changes"; }
  std::vector<std::string> Integrate(const std::string& store) const {
    return {"map", "integrate", "--quiet", "--store", store, "--aligned", aligned(), "--changes", changes()};
  }

  // `map integrate` of session_01 into a copy of the pristine store in `dir`, out of space as
  // `space` says. Returns whether it failed. The property: an error naming the store with the
  // previous state intact, or the next state committed in -wal and an error saying to keep it;
  // else success with the store file alone holding the integration. Either way the same
  // command run with space again ends with the integrated store in one file.
  bool IntegrateTrial(const std::string& dir, const Space& space) {
    SCOPED_TRACE(space.Describe());
    fs::create_directories(dir);
    const std::string store = dir + "/m.ltmap";
    fs::copy_file(pristine_, store);
    const Result r = RunIn(space, Integrate(store));
    const bool failed = r.rc != 0;
    if (failed) {
      EXPECT_LT(r.rc, 126) << "not an error exit (signal or exec failure):\n" << r.out;
      EXPECT_NE(r.out.find(store), std::string::npos) << "the error does not name the store:\n" << r.out;
      const std::uint64_t d = DigestWithWal(store, tmp_ / "scratch");
      if (d == before_) {
        ++n_previous_;
      } else {
        EXPECT_EQ(d, after_) << "neither the previous nor the integrated state:\n" << r.out;
        EXPECT_NE(r.out.find("-wal"), std::string::npos) << "committed in -wal, but the error does not say so:\n"
                                                         << r.out;
        ++n_in_wal_;
      }
      // Run again still out of space: an error again, or success with the store file complete
      // (it exited 0, nothing left to integrate, with the data still only in -wal).
      const Result still = RunIn(space, Integrate(store));
      if (still.rc == 0)
        EXPECT_EQ(DigestAlone(store, tmp_ / "scratch"), after_) << "run again, still out of space:\n" << still.out;
      else
        EXPECT_NE(still.out.find(store), std::string::npos) << still.out;
      const Result again = RunLtm(Integrate(store), -1);
      EXPECT_EQ(again.rc, 0) << "run again with space:\n" << again.out;
    } else {
      ++n_complete_;
    }
    EXPECT_EQ(DigestAlone(store, tmp_ / "scratch"), after_) << "the store file alone lacks the integration:\n" << r.out;
    EXPECT_FALSE(fs::exists(store + "-wal")) << "a -wal left after a command that succeeded";
    fs::remove_all(dir);
    return failed;
  }

  // `map init` of a new store in `dir`: an error leaves no store and no temporary, success a
  // complete one.
  bool InitTrial(const std::string& dir, const Space& space) {
    SCOPED_TRACE(space.Describe());
    fs::create_directories(dir);
    const std::string store = dir + "/m.ltmap";
    const Result r =
        RunIn(space, {"map", "init", "--quiet", "--store", store, "--aligned", aligned(), "--changes", changes()});
    const bool failed = r.rc != 0;
    if (failed) {
      EXPECT_LT(r.rc, 126) << r.out;
      EXPECT_NE(r.out.find(store), std::string::npos) << "the error does not name the store:\n" << r.out;
      EXPECT_FALSE(fs::exists(store)) << "a failed init left a store under the final name";
      EXPECT_EQ(NamesWith(dir, ".tmp-"), std::vector<std::string>{}) << "temporaries left behind";
    } else {
      EXPECT_EQ(DigestAlone(store, tmp_ / "scratch"), before_);
    }
    fs::remove_all(dir);
    return failed;
  }

  // `map export` of the integrated store to `dir`/e.pcd, where an earlier export already lies:
  // an error names e.pcd and leaves the earlier file as it was, with no temporary.
  bool ExportTrial(const std::string& dir, const Space& space) {
    const std::string store = tmp_ / "full/m.ltmap";
    SCOPED_TRACE(space.Describe());
    fs::create_directories(dir);
    const std::string pcd = dir + "/e.pcd";
    test::WriteText(pcd, "an earlier export");
    const Result r = RunIn(space, {"map", "export", "--quiet", "--voxel", "0", "--store", store, "--out", pcd});
    const bool failed = r.rc != 0;
    if (failed) {
      EXPECT_LT(r.rc, 126) << r.out;
      EXPECT_NE(r.out.find(pcd), std::string::npos) << "the error does not name the file:\n" << r.out;
      EXPECT_EQ(test::ReadText(pcd), "an earlier export");
      EXPECT_EQ(NamesWith(dir, ".tmp-"), std::vector<std::string>{}) << "temporaries left behind";
    } else {
      EXPECT_EQ(io::ReadPcd(pcd).size(), io::ReadPcd(tmp_ / "full_export.pcd").size());
    }
    fs::remove_all(dir);
    return failed;
  }

  // LT-removert of one session into `dir`/changes, which holds an earlier complete output: an
  // error names the file that did not fit and leaves the earlier output as it was, with no
  // temporary folder next to it.
  bool StageTrial(const std::string& dir, const Space& space) {
    const auto& earlier = earlier_stage_;
    SCOPED_TRACE(space.Describe());
    const std::string out = dir + "/changes";
    fs::create_directories(out);
    for (const auto& [name, text] : earlier) test::WriteText(out + "/" + name, text);
    EXPECT_TRUE(Contents(out) == earlier) << "no room for the earlier output";
    const Result r = RunIn(space, Removert(out));
    const bool failed = r.rc != 0;
    if (failed) {
      EXPECT_LT(r.rc, 126) << r.out;
      EXPECT_NE(r.out.find(out), std::string::npos) << "the error does not name the output:\n" << r.out;
      EXPECT_TRUE(Contents(out) == earlier) << "the earlier output changed:\n" << r.out;
      EXPECT_EQ(NamesWith(dir, ".tmp-"), std::vector<std::string>{}) << "temporaries left behind";
      EXPECT_EQ(NamesWith(dir, ".old-"), std::vector<std::string>{}) << "temporaries left behind";
    } else {
      EXPECT_TRUE(fs::exists(out + "/session/static_map.pcd"));
    }
    fs::remove_all(dir);
    return failed;
  }
  // The integrated store's export (e_bytes_) and an LT-removert output (earlier_stage_) made
  // with space, for the output trials.
  void MakeOutputs() {
    const Result e = RunLtm(
        {"map", "export", "--quiet", "--voxel", "0", "--store", tmp_ / "full/m.ltmap", "--out", tmp_ / "full_export.pcd"}, -1);
    ASSERT_EQ(e.rc, 0) << e.out;
    e_bytes_ = Size(tmp_ / "full_export.pcd");
    const Result s = RunLtm(Removert(tmp_ / "stage/changes"), -1);
    ASSERT_EQ(s.rc, 0) << s.out;
    earlier_stage_ = Contents(tmp_ / "stage/changes");
    for (const auto& [name, text] : earlier_stage_) {
      stage_bytes_ += text.size();
      largest_ = std::max(largest_, text.size());
    }
  }
  std::vector<std::string> Removert(const std::string& out) {
    if (!fs::exists(tmp_ / "session")) {
      io::WriteKittiPoses(tmp_ / "session_poses.txt", test::WriteStreetSession(tmp_ / "session", 0.0, 3, true));
    }
    return {"removert", "--quiet", "--threads", "2", "--sessions", tmp_ / "session", "--poses",
            tmp_ / "session_poses.txt", "--out", out};
  }

  test::TempDir tmp_;
  std::string pristine_;
  std::uint64_t before_ = 0, after_ = 0;
  std::size_t p_bytes_ = 0, a_bytes_ = 0;
  int n_previous_ = 0, n_in_wal_ = 0, n_complete_ = 0;
  std::size_t e_bytes_ = 0, stage_bytes_ = 0, largest_ = 0;
  std::map<std::string, std::string> earlier_stage_;
};

// Integration into a store whose files may not grow past a limit: from 8 KiB (not even the WAL
// fits) through the store's size (the checkpoint cannot grow the file) to twice the result.
TEST_F(DiskFull, IntegrateUnderFileSizeLimit) {
  const long long P = (long long)p_bytes_, A = (long long)a_bytes_;
  std::vector<long long> limits = {8 << 10, P / 4, P / 2, P, P + (A - P) / 4, P + (A - P) / 2, A - 4096, 2 * A};
  int failed = 0;
  for (std::size_t i = 0; i < limits.size(); ++i) failed += IntegrateTrial(tmp_ / ("t" + std::to_string(i)), {limits[i]});
  std::printf("integrate under RLIMIT_FSIZE: %zu trials, %d errors with the previous state, %d with the next one in "
              "-wal, %d complete\n", limits.size(), n_previous_, n_in_wal_, n_complete_);
  EXPECT_GE(failed, 3) << "the small limits must fail";
  EXPECT_GE(n_complete_, 1) << "twice the store's size must be enough";
}

TEST_F(DiskFull, InitUnderFileSizeLimit) {
  const long long P = (long long)p_bytes_;
  for (long long limit : {8LL << 10, P / 2, P - 8192})
    EXPECT_TRUE(InitTrial(tmp_ / "init", {limit})) << limit << " bytes must not be enough";
  EXPECT_FALSE(InitTrial(tmp_ / "init", {2 * P}));
}

// A PCD export and a stage output folder that do not fit: errors, earlier outputs intact.
TEST_F(DiskFull, OutputsUnderFileSizeLimit) {
  ASSERT_NO_FATAL_FAILURE(MakeOutputs());
  const long long E = (long long)e_bytes_, L = (long long)largest_;
  EXPECT_TRUE(ExportTrial(tmp_ / "export", {E / 2}));
  EXPECT_TRUE(ExportTrial(tmp_ / "export", {E - 1}));
  EXPECT_FALSE(ExportTrial(tmp_ / "export", {E})) << "exactly its size fits";
  ASSERT_GT(L, 8192);
  EXPECT_TRUE(StageTrial(tmp_ / "stage2", {L / 2}));
  EXPECT_FALSE(StageTrial(tmp_ / "stage2", {L})) << "each file fits";
}

// The same on a real full file system: a small tmpfs filled up to a few bytes (ENOSPC).
TEST_F(DiskFull, SmallTmpfs) {
  ASSERT_NO_FATAL_FAILURE(MakeOutputs());
  const std::size_t P = p_bytes_, A = a_bytes_, E = e_bytes_;
  SmallTmpfs small(tmp_ / "tmpfs", 4 * (A + E + stage_bytes_) + (1 << 20));
  if (!small.mounted()) GTEST_SKIP() << small.reason() << "; the RLIMIT_FSIZE trials cover the same paths";
  const std::string d = small.dir() + "/t";
  int failed = 0;
  const std::vector<std::size_t> frees = {0, 16 << 10, P / 2, P, 3 * A};
  for (std::size_t f : frees) failed += IntegrateTrial(d, Space{-1, &small, f});
  std::printf("integrate on a full tmpfs: %zu trials, %d errors with the previous state, %d with the next one in "
              "-wal, %d complete\n", frees.size(), n_previous_, n_in_wal_, n_complete_);
  EXPECT_GE(failed, 2);
  EXPECT_GE(n_complete_, 1);
  EXPECT_TRUE(InitTrial(d, Space{-1, &small, P / 2}));
  EXPECT_FALSE(InitTrial(d, Space{-1, &small, 3 * A}));
  EXPECT_TRUE(ExportTrial(d, Space{-1, &small, E / 2}));
  EXPECT_FALSE(ExportTrial(d, Space{-1, &small, 2 * E + (64 << 10)}));
  EXPECT_TRUE(StageTrial(d, Space{-1, &small, largest_ / 2}));
  EXPECT_FALSE(StageTrial(d, Space{-1, &small, 3 * stage_bytes_ + (256 << 10)}));
}

}  // namespace
}  // namespace ltm
