#pragma once
/// \file
/// The `diagnose:` section of a scenario (yaml/SCHEMA.md): which candidates, how
/// many refits, the significance level and the held-out motions.
#include <string>
#include <vector>

namespace kelvin {

/// The missing-force field of the "where" stage (diagnose/missing_force.hpp).
struct MissingForceSettings {
  bool enabled = true;
  int evaluations = 20;  // fit evaluations (each one forward + adjoint run)
  /// Time resolution (resolves about a quarter of it in Hz); 0: four per period at
  /// the top of the band below which 90 % of the nominal residual's power lies (or
  /// 95 % of the observed motion's, if lower).
  double knots_per_second = 0;
  int segments = 6;  // boxes along the body's axis
};

struct DiagnoseSettings {
  std::vector<std::string> candidates;  // identifiers; empty = every built-in that applies
  /// The learned correction after failed named refits: on by default, and with a
  /// candidates list only when it names "unnamed".
  bool learned_correction = true;
  int refits = 3;  // top candidates refitted
  /// Evaluations a refit may take: its verdict rests on misfit differences far above
  /// the last digits a long tail of L-BFGS iterations buys.
  int refit_evaluations = 40;
  double alpha = 0.01;                // family-wise significance level
  std::vector<std::string> validate;  // held-out scenario files (absolute)
  MissingForceSettings missing_force;
};

/// Reads the section from the scenario file (defaults when it has none); errors
/// name the file, line and key.
DiagnoseSettings load_diagnose_settings(const std::string& scenario_path);

}  // namespace kelvin
