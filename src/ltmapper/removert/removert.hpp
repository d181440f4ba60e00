// ltmapper removert: LT-removert (LT-mapper paper, section "LT-removert").
//
//   HD removal   per session, remove-then-revert on multi-resolution range images (Removert,
//                Kim & Kim, IROS 2020): a map point that a keyframe scan *sees through* (the
//                scan's range at the point's pixel exceeds the point's range by a tolerance)
//                gets a vote; points with enough votes at any removal resolution (fine to
//                coarse) are removed; removed points that enough keyframes observe as a surface
//                at a coarser revert resolution are reverted (false removals at grazing angles,
//                edges and thin structures).
//   LD detection between the HD-free central and query maps (kd-tree: fewer than k neighbours
//                within r in the other session = change): ND from central, PD from query. A
//                raw change whose surface the other session's scans observed (BeamTest: the two
//                beams around the exact ray towards it) and did not see through is the same
//                surface sampled more sparsely (far ground between rings): no change
//                (ld.same_min_hits).
//   Occlusion    ND the query never saw through = weak ND (kept in the map); PD in space some
//                central scan saw through (observed free) = weak PD; otherwise strong.
//
// All work is per keyframe and parallel (TBB, threads passed in); scans are streamed from disk
// (at most one per worker in memory) and each keyframe only touches the map points within
// `submap_radius_m` of it (tile index), so memory is the maps of at most two sessions (the
// central and the current query: a session's maps are freed when no later pair needs them) plus
// O(threads) scans; it still grows with the length of a session (its whole map is in memory),
// unless HD removal and LD run tile by tile from files (tiles.hpp: the same maps and changes,
// memory bounded by the tile).
//
// This header only gathers the module's parts, one topic each (include the part you need):
// config.hpp, keyframes.hpp, hd.hpp, ld.hpp, visibility.hpp, stage.hpp, tiles.hpp.
#pragma once

#include "ltmapper/removert/config.hpp"
#include "ltmapper/removert/keyframes.hpp"
#include "ltmapper/removert/hd.hpp"
#include "ltmapper/removert/ld.hpp"
#include "ltmapper/removert/visibility.hpp"
#include "ltmapper/removert/stage.hpp"
#include "ltmapper/removert/tiles.hpp"
