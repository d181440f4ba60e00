// ltmapper slam: LT-SLAM, the multi-session SLAM engine of the LT-mapper paper (section "LT-SLAM").
//
// Every session keeps its own odometry frame; one anchor pose per session, A_s = T_world_session,
// places it in the shared world frame (world = the central session's frame, A_0 = identity):
//   T_world_sensor = A_s * T_session_sensor                                     (paper eq. 3)
// Inter-session loops come from Scan Context retrieval, are verified by GICP between keyframe
// submaps and enter a Ceres pose graph through the anchors with a robust loss:
//   r = Log( z^-1 * (A_a * x_a)^-1 * (A_b * x_b) )                               (paper eq. 2)
// PCL (FPFH global registration) and Ceres are used only inside the .cpp files.
//
// This header only gathers the module's parts, one topic each (include the part you need):
// config.hpp, registration.hpp, alignment.hpp.
#pragma once

#include "ltmapper/slam/config.hpp"
#include "ltmapper/slam/registration.hpp"
#include "ltmapper/slam/alignment.hpp"
