#pragma once
/// \file
/// One parameter set per static measurement (Bächer 2008, ch. 6), how they are
/// stored (`sets/<measurement>.csv` beside a probe-fit's other outputs), and the
/// leave-one-out cross-validation that says whether blending them predicts a new
/// contact better than one set fitted to all of them.
#include <string>
#include <vector>

#include "probing/blending.hpp"
#include "probing/displacement_inverse.hpp"
#include "probing/force_inverse.hpp"

namespace kelvin {

/// Fits each measurement alone with the displacement-based inverse (its models are
/// left at their own sets) and records the strain at that set's equilibrium.
/// names: the measurements', in order.
std::vector<ParameterSet> fit_parameter_sets(std::vector<ObservedProbe>& measurements,
                                             const std::vector<std::string>& names,
                                             const DisplacementInverseOptions& options);

/// One set per measurement from the force-based inverse, all fitted at once with the
/// smoothness across measurements (options.gamma_measurement, Bächer §5.2.2), each
/// with the strain at its measured positions; options.per_measurement is implied.
std::vector<ParameterSet> force_parameter_sets(const std::vector<StaticState>& measurements,
                                               const std::vector<std::string>& names,
                                               ForceInverseOptions options);

/// `element,elastic.<p>…,strain.E11,…,strain.E12` rows (the strain as in
/// element_strains).
std::string parameter_set_csv(const std::vector<std::string>& parameters, const ParameterSet& set);
/// Reads what parameter_set_csv wrote; throws kelvin::Error naming the file and line
/// when its columns are not `parameters` or its rows not the mesh's elements.
ParameterSet read_parameter_set(const std::string& path, const std::string& name,
                                const std::vector<std::string>& parameters, int elements);

struct BlendedPrediction {
  double rms = 0;  // marker distance (m, per coordinate) to the held-out measurement
  int passes = 0;
  bool converged = false;  // the weights settled
};

struct CrossValidationFold {
  std::string held_out;
  double single_rms = 0;                   // of one set fitted to the other measurements
  std::vector<BlendedPrediction> blended;  // per blend in `blends`, of their sets blended
};

/// Leave-one-out over the measurements (at least 3): each held out in turn, the rest
/// fitted as one set and as per-measurement sets, the held-out contact predicted by
/// the one set and by each blend of the sets. The models are left at unspecified
/// values.
std::vector<CrossValidationFold> cross_validate_blending(std::vector<ObservedProbe>& measurements,
                                                         const std::vector<std::string>& names,
                                                         const DisplacementInverseOptions& fit,
                                                         const std::vector<BlendOptions>& blends);

/// Marker distance per coordinate (m) between the positions at full nodal positions x
/// and a measurement's observed ones (occluded ones left out).
double marker_rms(const ObservedProbe& probe, const Eigen::Matrix3Xd& x);

}  // namespace kelvin
