// ltmapper eval: scores every stage against ground truth (usually the simulator's truth/).
//
//   trajectories  ATE (after one rigid alignment), RPE, inter-session consistency
//   hd            point-wise SA / DA / AA of HD removal (KTH DynamicMap benchmark rule)
//   ld            precision / recall / F1 of PD and ND points, strong and weak
//   restore       the LT-mapper paper's Chamfer table over cubic patches
//   storage       bytes on disk, wall time and peak memory of a stage
//
// Every metric is a plain function returning a result struct; a Report gathers them and is
// written as JSON (machines) and Markdown (people). Undefined ratios (0/0) are NaN in the
// structs, `null` in JSON and "n/a" in Markdown. Depends on core; io, geometry and TBB are used
// only inside the .cpp files.
//
// This header only gathers the module's parts, one topic each (include the part you need):
// config.hpp, trajectory.hpp, hd.hpp, ld.hpp, restore.hpp, truth_mapping.hpp, livemeta.hpp,
// objects.hpp, storage.hpp, report.hpp, truth_io.hpp, ld_case.hpp.
#pragma once

#include "ltmapper/eval/config.hpp"
#include "ltmapper/eval/trajectory.hpp"
#include "ltmapper/eval/hd.hpp"
#include "ltmapper/eval/ld.hpp"
#include "ltmapper/eval/restore.hpp"
#include "ltmapper/eval/truth_mapping.hpp"
#include "ltmapper/eval/livemeta.hpp"
#include "ltmapper/eval/objects.hpp"
#include "ltmapper/eval/storage.hpp"
#include "ltmapper/eval/report.hpp"
#include "ltmapper/eval/truth_io.hpp"
#include "ltmapper/eval/ld_case.hpp"
