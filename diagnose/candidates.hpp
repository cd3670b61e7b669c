#pragma once
/// \file
/// The built-in candidate effects of the gap diagnosis. Each is a nested extension
/// of the nominal scenario written as edits of its YAML (terms added to the
/// material, entries added to fit.parameters), so that an extended model is an
/// ordinary scenario file: loaded, checked and runnable like any other, and its
/// refit's fitted.yaml runs in `kelvin simulate`.
#include <yaml-cpp/yaml.h>

#include <functional>
#include <string>
#include <vector>

#include "diagnose/diagnose_settings.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

/// The parts of the scenario's YAML that candidates edit: the material's term lists
/// as sequences, to which they append, and the clamps.
struct ModelEdits {
  YAML::Node elastic, viscous;         // sequences of term mappings
  YAML::Node clamps;                   // the `clamps:` sequence (undefined without one)
  YAML::Node root;                     // the whole scenario (the mesh and solver sections)
  const MaterialSpec* spec = nullptr;  // the nominal material as loaded
};

struct Candidate {
  std::string id;           // stable identifier in diagnosis.json (stiffening, drag, ...)
  std::string where;        // the marker it concerns ("" = the body or the capture)
  std::string description;  // one line for the report
  /// false: no parameters of its own (the discretisation); judged by one run at the
  /// nominal fit instead of the score, and refitted with the nominal parameters.
  bool screened = true;
  /// Where the user defined it (diagnose.custom, "file:line:col: key"); "" if built in.
  std::string origin;
  /// Screened as alternatives, one parameter entry each (the anisotropy's fibre
  /// directions, the relaxation's times): `choice` is the one that explained most,
  /// which the refit starts from (−1 before screening).
  bool alternatives = false;
  int choice = -1;
  /// Adds the candidate's terms to `material` and its parameter entries (mappings)
  /// to `parameters`. `screening`: the form scored at the nominal fit (the
  /// anisotropy's moduli along fixed directions) rather than the one refitted.
  std::function<void(const Candidate& self, ModelEdits& material, YAML::Node& parameters,
                     bool screening)>
      extend;
};

/// How the body lies: its long axis, and which end the clamps hold.
struct BodyAxis {
  int axis = 2;          // 0, 1, 2 = x, y, z
  double clamp_end = 0;  // coordinate of the clamped end along the axis
  double free_end = 1;   // coordinate of the other end
  /// 0 at the clamp, 1 at the free end.
  double along(const Eigen::Vector3d& x) const {
    return (x[axis] - clamp_end) / (free_end - clamp_end);
  }
};
BodyAxis body_axis(const Scenario& scenario);

/// The nominal material's largest quantity in Pa (1 when it has none): the scale of
/// the pads' compliance and of the learned correction's stresses.
double largest_modulus(const Scenario& scenario);

/// Every built-in candidate that applies to `scenario` (a damping law needs a
/// Newtonian term, a marker offset an observed marker), in a fixed order, those not
/// screened (Candidate::screened) last.
std::vector<Candidate> builtin_candidates(const Scenario& scenario);

/// The user's candidate of diagnose.custom (screened and refitted like a built-in one).
Candidate custom_candidate(const CustomCandidateSpec& spec);

/// Identifiers the diagnosis knows, for the `diagnose.candidates` check ("unnamed",
/// the learned correction of diagnose/learned_correction, is not screened: it is
/// refitted when no named candidate passes).
const std::vector<std::string>& candidate_ids();

/// The fibre directions the anisotropy is screened along: axes, face and body
/// diagonals of the frame (13 directions, a⊗a⊗a⊗a spanning 13 of the 15 fully
/// symmetric fourth-order tensors).
std::vector<Eigen::Vector3d> screening_directions();

/// The relaxation times a relaxing branch is screened at: from two frames of the
/// capture up to half its duration, a factor 3 apart (the branch damps most where
/// ωτ ≈ 1, so these cover the captured band).
std::vector<double> screening_relaxation_times(const Scenario& scenario);

}  // namespace kelvin
