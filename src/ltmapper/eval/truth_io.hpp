// ltmapper eval: finding and reading the inputs (docs/FORMATS.md): the simulator's truth
// folders, pose files and the stage outputs the CLI scores.
#pragma once

#include "ltmapper/eval/hd.hpp"
#include "ltmapper/eval/ld.hpp"
#include "ltmapper/eval/trajectory.hpp"

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace ltm::eval {

// (docs/FORMATS.md) Helpers the CLI uses to find inputs in a sim dir and stage outputs.

// KITTI (12 numbers per line) or TUM (8) pose file, detected from the first data line.
std::vector<Pose> ReadPoses(const std::string& path);
// Session names under DIR/truth (session_XX folders), sorted.
std::vector<std::string> SimSessionNames(const std::string& sim_dir);
// Truth poses DIR/truth/<s>/poses_world.txt with estimates from `est_dir/<s>/poses_world.txt`
// (an aligned/ dir) or, when est_dir is empty, the drifted session poses
// DIR/sessions/<s>/optimized_poses.txt. Sessions without an estimate are listed in *missing.
std::vector<SessionTrajectory> LoadSimTrajectories(const std::string& sim_dir,
                                                   const std::string& est_dir,
                                                   std::vector<std::string>* missing);
// DIR/truth/objects.csv -> id -> class (empty map when the file is absent).
std::map<int, std::string> ReadObjectClasses(const std::string& objects_csv);
// Paths of the labelled scans <session_truth_dir>/labels/*.ply in keyframe order; ltm::Error
// naming the folder when it is missing or holds other than `keyframes` scans.
std::vector<std::string> LabelledScanPaths(const std::string& session_truth_dir, std::size_t keyframes);
// One labelled scan (PLY with a per-point 'class' field, else ltm::Error naming the file).
PointCloud ReadLabelledScan(const std::string& path);
// Feeds a session's labelled scans (truth/<session>/labels/*.ply) placed with
// T_frame_sensor[k] (one per keyframe, keyframe order) into `ev`; returns scans used.
std::size_t AddSimSessionTruth(HdEvaluator& ev, const std::string& sim_dir,
                               const std::string& session, const std::vector<Pose>& T_frame_sensor,
                               const EvalConfig& cfg);
// Transform taking the sim's true world frame into the estimated world frame: the inverse of
// the joint ATE alignment when `aligned_dir` is given, else the inverse of the central
// session's true origin (world = central session frame, as LT-SLAM defines it).
Pose TruthToEstimateFrame(const std::string& sim_dir, const std::string& aligned_dir);
// The four change clouds {pd_strong,pd_weak,nd_strong,nd_weak}.pcd of a pair folder.
ChangeClouds ReadChangeClouds(const std::string& dir);
// The truth's points of changed objects alone (objects_{pd,nd}_{strong,weak}.pcd, as the simulator
// writes them beside the full clouds); nullopt when any of the four is missing.
std::optional<ChangeClouds> ReadObjectChangeClouds(const std::string& dir);
ChangeClouds TransformChanges(const ChangeClouds& c, const Pose& T);
// A session's HD-free map after LT-removert's multi-session cleanup (paper Fig. 3(f)): its
// <changes>/<session>/static_map.pcd minus the residues of movers that the pairs of report.json
// holding it found (nd_residue.pcd where it is the central, pd_residue.pcd where it is the
// query; points within cfg.ld_same_point_m, WithoutPoints). Without report.json (no pairs): the
// static map; a session report.json does not list: ltm::Error. `note` says what was taken out.
PointCloud CleanedSessionMap(const std::string& changes, const std::string& session, const EvalConfig& cfg,
                             int threads, std::string* note);
// `root/pair_<pair>`; pair "00_01" also finds pair_session_00_session_01 and any pair_*
// folder whose two trailing numbers are 00 and 01. Throws listing what exists when none.
std::string FindPairDir(const std::string& root, const std::string& pair);

}  // namespace ltm::eval
