#pragma once
/// \file
/// The `diagnose:` section of a scenario (yaml/SCHEMA.md): which candidates, how
/// many refits, the significance level and the held-out motions.
#include <yaml-cpp/yaml.h>

#include <string>
#include <vector>

namespace kelvin {

/// A candidate effect of the user's (`diagnose.custom`): at most one material term
/// added to the nominal ones and the fit entries of its parameters, written into each
/// extended model like a built-in candidate. It must be nested: at its entries' start
/// values the model is the nominal one (the diagnosis checks this with one run).
struct CustomCandidateSpec {
  std::string id, description, where;
  std::string kind;       // "elastic", "viscous", or "" (no term: a field or observation)
  YAML::Node term;        // the added term's mapping (its plugin path made absolute)
  YAML::Node parameters;  // fit entries; a target `term.<p>` names the added term's p
  std::string place;      // "file:line:col: diagnose.custom[i]", for messages about it
};

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
  std::vector<std::string> exclude;     // identifiers left out of `candidates` or the default
  /// The learned correction after failed named refits: on by default, and with a
  /// candidates list only when it names "unnamed".
  bool learned_correction = true;
  int refits = 3;  // top candidates refitted
  /// Evaluations a refit may take: its verdict rests on misfit differences far above
  /// the last digits a long tail of L-BFGS iterations buys.
  int refit_evaluations = 40;
  double alpha = 0.01;                // family-wise significance level
  std::vector<std::string> validate;  // held-out scenario files (absolute)
  std::vector<CustomCandidateSpec> custom;
  MissingForceSettings missing_force;
};

/// Reads the section from the scenario file (defaults when it has none); errors
/// name the file, line and key.
DiagnoseSettings load_diagnose_settings(const std::string& scenario_path);

}  // namespace kelvin
