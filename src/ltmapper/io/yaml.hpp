// ltmapper io: YAML params files read into / written from any config with a Visit().
#pragma once

#include "ltmapper/core/core.hpp"

#include <string>

namespace ltm::io {

// Reads a YAML params file into any config with a Visit() (see core.hpp). Nested maps are
// flattened to dotted keys. Unknown keys, wrong types and out-of-range values are errors
// naming the file and key. Keys absent from the file keep their defaults. `section` selects a
// top-level map (other top-level keys are ignored; an absent section keeps every default). A file
// with any error changes nothing (values are applied only when the whole file is valid).
void LoadConfigFields(const std::string& path, const ConfigFields& fields,
                      const std::string& section = "");
template <class Config>
void LoadConfig(const std::string& path, Config& cfg, const std::string& section = "") {
  LoadConfigFields(path, FieldsOf(cfg), section);
  ValidateConfig(cfg, path);
}
// Writes the config as YAML (nested maps for dotted keys), e.g. to record the resolved params.
void SaveConfigFields(const std::string& path, const ConfigFields& fields);

}  // namespace ltm::io
