// Lifelong add (LT-SLAM side): a new session aligned to a world frame that is already built.
// The sessions in the map keep their world poses; the new one gets its anchor from loops to one
// of them (paper eq. 2 with the reference's anchor fixed at identity).
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/slam.hpp"

#include <cmath>
#include <filesystem>

namespace ltm::slam {
namespace fs = std::filesystem;

namespace {
// The reference's rebuilt odometry is this many times stiffer (in standard deviation) than an
// inter-session loop (registration.loop_sigma_*): loops move it by ~1e-3 of their pull.
constexpr double kReferenceStiffness = 1e3;
}  // namespace

Session WorldReference(Session session, const std::vector<Pose>& T_world_sensor, const SlamConfig& cfg) {
  if (T_world_sensor.size() != session.keyframes.size())
    throw Error("session '" + session.name + "': " + std::to_string(T_world_sensor.size()) +
                " world poses for " + std::to_string(session.keyframes.size()) + " keyframes");
  Matrix6d info = Matrix6d::Zero();
  const double st = cfg.loop_sigma_t_m / kReferenceStiffness;
  const double sr = cfg.loop_sigma_r_deg * M_PI / 180.0 / kReferenceStiffness;
  for (int i = 0; i < 3; ++i) {
    info(i, i) = 1.0 / (st * st);
    info(i + 3, i + 3) = 1.0 / (sr * sr);
  }
  session.odometry.clear();
  session.loops.clear();
  for (std::size_t k = 0; k < session.keyframes.size(); ++k) {
    session.keyframes[k].T_session_sensor = T_world_sensor[k];
    if (k == 0) continue;
    Edge e;
    e.from = session.keyframes[k - 1].index;
    e.to = session.keyframes[k].index;
    e.T_from_to = T_world_sensor[k - 1].inverse() * T_world_sensor[k];
    e.information = info;
    e.has_information = true;
    session.odometry.push_back(e);
  }
  return session;
}

SlamResult AlignToReference(const Session& reference, const Session& query, const SlamConfig& cfg, int threads) {
  SlamConfig c = cfg;
  c.use_g2o_information = true;  // the reference's stiffness is in its edges' information
  c.central_own_loops = false;    // the reference's poses are the world: no loop may bend them
  // The query's own edges: the file's information when the user's config says so, else the
  // config's sigmas (AlignSessions reads has_information per edge).
  Session q = query;
  if (!cfg.use_g2o_information) {
    for (auto* edges : {&q.odometry, &q.loops})
      for (Edge& e : *edges) e.has_information = false;
  }
  return AlignSessions({reference, q}, c, threads);
}

void WriteSessionAlignment(const std::string& aligned_dir, const std::string& folder, const SessionAlignment& a) {
  const std::string dir = (fs::path(aligned_dir) / folder).string();
  io::MakeDirs(dir);
  if (!a.aligned) {
    io::WriteFileAtomic(dir + "/NOT_ALIGNED.txt", [&](std::ostream& os) {
      os << "session " << a.name << " is NOT aligned to the world frame: " << a.reason << "\n";
    });
    return;
  }
  io::WriteKittiPoses(io::layout::PosesWorldFile(aligned_dir, folder), a.T_world_sensor);
  std::vector<io::StampedPose> st;
  for (std::size_t k = 0; k < a.T_world_sensor.size(); ++k) st.push_back({double(k), a.T_world_sensor[k]});
  io::WriteTumPoses(dir + "/poses_world_tum.txt", st);
  io::WriteKittiPoses(io::layout::AnchorFile(aligned_dir, folder), {a.anchor});
}

}  // namespace ltm::slam
