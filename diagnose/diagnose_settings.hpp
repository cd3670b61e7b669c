#pragma once
/// \file
/// The `diagnose:` section of a scenario (yaml/SCHEMA.md): which candidates, how
/// many refits, the significance level and the held-out motions.
#include <string>
#include <vector>

namespace kelvin {

struct DiagnoseSettings {
  std::vector<std::string> candidates;  // identifiers; empty = every built-in that applies
  int refits = 3;                       // top candidates refitted
  /// Evaluations a refit may take: its verdict rests on misfit differences far above
  /// the last digits a long tail of L-BFGS iterations buys.
  int refit_evaluations = 40;
  double alpha = 0.01;                // family-wise significance level
  std::vector<std::string> validate;  // held-out scenario files (absolute)
};

/// Reads the section from the scenario file (defaults when it has none); errors
/// name the file, line and key.
DiagnoseSettings load_diagnose_settings(const std::string& scenario_path);

}  // namespace kelvin
