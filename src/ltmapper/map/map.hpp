// ltmapper map: LT-map, the evolving multi-session map (paper "LT-map", "Change Composition",
// "Automatic Parsing of Ephemeral Objects").
//
// One SQLite file NAME.ltmap holds, per map keyframe, its HD-free cloud as of the LATEST session
// (the base) and, per session step, the delta that step applied, both in the keyframe's local
// frame. Composition (paper eq. 4) P ⊙ LD = P − ND + PD; the inverse delta (PD and ND swapped)
// rolls a keyframe back, so the map as of any session is rebuilt from the base without snapshots.
// The store schema, blob format and the reasons for "base = latest" are in README.md here.
// SQLite, zstd and PCL are used only inside the .cpp files.
//
// This header only gathers the module's parts, one topic each (include the part you need):
// config.hpp, records.hpp, store.hpp, diff.hpp, files.hpp.
#pragma once

#include "ltmapper/map/config.hpp"
#include "ltmapper/map/records.hpp"
#include "ltmapper/map/store.hpp"
#include "ltmapper/map/diff.hpp"
#include "ltmapper/map/files.hpp"
