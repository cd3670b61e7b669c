#pragma once
/// \file
/// The `probing:` section of a scenario: static measurements of the specimen, each
/// the loads a probe adds to the scenario's own (gravity, `loads:`) and the markers'
/// measured loaded positions, and how `kelvin probe-fit` inverts them.
#include <string>
#include <vector>

#include "engine/csv.hpp"
#include "probing/probing_system.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

struct ProbeMeasurementSpec {
  std::string name;
  std::vector<LoadSpec> loads;     // what a force-controlled probe adds to the scenario's loads
  std::vector<PressSpec> presses;  // probes pressed to a depth
  std::string observed_path;       // `name,x,y,z`; "" when not given (kelvin probe writes it)
  /// Per scenario marker (markers.rest order), its measured loaded position; NaN where
  /// the file has no row for it (occluded).
  Eigen::Matrix3Xd observed;
};

struct ProbingSpec {
  std::vector<ProbeMeasurementSpec> measurements;
  std::string method = "displacement";  // displacement | force
  ElementGrouping grouping = ElementGrouping::kGlobal;
  double gamma = -1;  // smoothness (relative); < 0: the L-curve (force) or 0 (displacement)
  /// Smoothness across the per-measurement sets of the force-based inverse (relative).
  double gamma_measurements = 1e-2;
  /// In a fit with captured motion: each measurement weighs like this many seconds
  /// of a captured track of its markers; < 0: the fitted scenario's duration.
  double weight = -1;
  /// The measurements' noise, marker coordinates (m) and reaction forces (N): a measured
  /// reaction's misfit weighs (markers/force)² against the markers'. Given together;
  /// needed when a reaction is measured; < 0 when not given.
  double marker_noise = -1, force_noise = -1;
  /// (marker_noise / force_noise)², m²/N²: the reaction misfit's weight; 0 without noise.
  double reaction_weight() const {
    return force_noise > 0 ? (marker_noise / force_noise) * (marker_noise / force_noise) : 0;
  }
};

/// True when the scenario file has a `probing:` section.
bool has_probing(const Scenario& scenario);

/// Reads `probing:` from the scenario file (after load_scenario succeeded on it).
/// Throws kelvin::Error "file:line:col: probing...: why" for a bad entry.
ProbingSpec load_probing(const Scenario& scenario);

}  // namespace kelvin
