#pragma once
/// \file
/// fitted.yaml: the input scenario file with the fitted parameters substituted,
/// runnable by `kelvin simulate` as it is. Global entries replace the scalar in
/// `material`; region, box and element entries go to a per-element field file
/// (fitted-fields.csv) that `material.fields` names. Relative paths of the input
/// are made absolute, since the file lives in another directory.
#include <string>

#include "adjoint/parameter_map.hpp"
#include "engine/fem_model.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

/// `model` holds the fitted values (map.apply already called). Writes
/// `<outdir>/fitted.yaml` (and fitted-fields.csv when needed) atomically and
/// returns the path of fitted.yaml. With the fitted vector `p`, the observation
/// parameters (clock offset, marker offsets, registration: the capture's, not the
/// model's) are listed in its header, and a one-entry one becomes the `initial` of
/// its fit entry, so that a further fit starts from it.
std::string write_fitted_scenario(const Scenario& scenario, const ParameterMap& map,
                                  const FemModel& model, const std::string& outdir,
                                  const Eigen::VectorXd& p = {});

}  // namespace kelvin
