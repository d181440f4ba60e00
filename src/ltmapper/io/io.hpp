// ltmapper io: every file format users already have, read and written.
//
// All readers throw ltm::Error naming the file (and line where there is one). All writers write
// to a temporary name in the same directory and rename, so a crash never leaves a partial file.
// PCL and yaml-cpp are used only inside the .cpp files.
//
// This header only gathers the module's parts, one topic each (include the part you need):
// files.hpp, formats.hpp, session.hpp, yaml.hpp, json.hpp.
#pragma once

#include "ltmapper/io/files.hpp"
#include "ltmapper/io/formats.hpp"
#include "ltmapper/io/session.hpp"
#include "ltmapper/io/yaml.hpp"
#include "ltmapper/io/json.hpp"
