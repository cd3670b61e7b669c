#pragma once
/// \file
/// What `kelvin diagnose` leaves in its output directory: diagnosis.json (the
/// verdict and every figure behind it, for scripts), report.md with SVG plots (for
/// people), where-markers.csv, and fitted.yaml of the accepted model.
#include <string>

#include "diagnose/diagnosis.hpp"

namespace kelvin {

/// Writes every output atomically; returns the report's path.
std::string write_diagnosis_outputs(const Diagnosis& d);

}  // namespace kelvin
