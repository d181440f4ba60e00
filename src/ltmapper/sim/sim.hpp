// ltmapper sim: a seeded, deterministic multi-session urban LiDAR simulator with point-wise
// ground truth (docs/FORMATS.md "Simulator output").
//
// A street-grid city block (ground with relief and curbs, buildings with facade bays, walls,
// fences, poles, trees, parked cars) is built as triangle meshes and ray-cast with Embree 3 by a
// spinning LiDAR. Each session drives its own route over the same streets, starts at its own
// unknown origin T_world_session and has drifting odometry; high dynamic (HD) actors move during
// a session and low dynamic (LD) objects exist only in some sessions. Embree stays inside the
// .cpp files.
//
// Determinism: the scenario comes from one 64-bit seed through our own generator (no std
// distributions); the noise of every ray is a hash of (seed, session, keyframe, ray), so the
// thread count never changes a byte of the output.
//
// This header only gathers the module's parts, one topic each (include the part you need):
// config.hpp, simulator.hpp.
#pragma once

#include "ltmapper/sim/config.hpp"
#include "ltmapper/sim/simulator.hpp"
