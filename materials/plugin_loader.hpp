#pragma once
/// \file
/// Loading material models from plugin libraries (plugin_abi.h). Every failure —
/// missing file, missing symbol, ABI mismatch, unknown model — is a kelvin::Error
/// naming the path; a model that throws or returns NaN/Inf is reported with the
/// element and the state (F, Ḟ) that triggered it.
#include <memory>
#include <string>
#include <vector>

#include "materials/material.hpp"

namespace kelvin {

/// The model `name` from the plugin at `path` (`name` may be empty when the plugin
/// exports exactly one model).
std::unique_ptr<Material> load_plugin_material(const std::string& path, const std::string& name);

/// Names of the models a plugin exports.
std::vector<std::string> plugin_material_names(const std::string& path);

/// "major.minor.patch" of an ABI version number.
std::string abi_version_string(std::uint32_t version);

}  // namespace kelvin
