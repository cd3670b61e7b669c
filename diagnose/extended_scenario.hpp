#pragma once
/// \file
/// A scenario file extended by candidate effects: the nominal file's YAML with the
/// candidates' terms added to its material and a fit section whose parameters are
/// the nominal ones followed by each candidate's, every path made absolute.
#include <string>
#include <vector>

#include "diagnose/candidates.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

struct ExtendedScenario {
  std::string path;
  int nominal_specs = 0;  // fit.parameters[0 … nominal_specs) are the nominal ones
  /// Per candidate, its entries of fit.parameters.
  std::vector<std::vector<int>> candidate_specs;
};

/// Writes `path` (atomically) from the scenario file `source` (a training or a
/// held-out motion), with `nominal` (the training scenario as loaded) giving the
/// material and the nominal fit parameters, and the fit to run in one stage at the
/// scenario's tolerances. With `screening` the candidates take their screened form,
/// except candidates[refit_form] (an effect already accepted, screened against).
ExtendedScenario write_extended_scenario(const std::string& source, const Scenario& nominal,
                                         const std::vector<const Candidate*>& candidates,
                                         bool screening, const std::string& path,
                                         int refit_form = -1);

}  // namespace kelvin
