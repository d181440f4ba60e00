// Private to the eval module (not installed): the task arena and the match count its .cpp files
// share. TBB stays out of the public headers.
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/geometry/geometry.hpp"

#include <tbb/task_arena.h>

#include <cstddef>

namespace ltm::eval::detail {

// A task arena of `threads` workers (0 = all cores) for a metric's parallel loops and reductions.
tbb::task_arena MakeArena(int threads);

// Number of points of `queries` with a point of `tree` within `dist` (0 when either is empty).
std::size_t CountMatched(const PointCloud& queries, const geometry::KdTree& tree, double dist,
                         tbb::task_arena& arena);

}  // namespace ltm::eval::detail
