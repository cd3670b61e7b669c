#pragma once
/// \file
/// The parameter map turns the optimiser's vector p into model quantities: each
/// block names one slot (a material parameter or the density). A value block
/// assigns every element one entry of p (global: all the same; per region; per
/// box; per element), with q = exp(p) for log-transformed blocks. A multiplier
/// block scales a field by exp(Σ_j B_ej p_j), with B the indicator of the scope's
/// regions or a Legendre basis along an axis: p = 0 is the model without it (a
/// nested extension). A slot's value is its value block's (or the scenario's) times
/// every multiplier acting on it, so a modulus can be fitted and scaled at once.
/// Several blocks can share entries of p (elastic.moduli: one multiplier for every
/// modulus).
/// Gradients reach p through for_each_dependency (∂q per slot and element over ∂p).
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "engine/fem_model.hpp"
#include "engine/param_derivatives.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

struct ParameterBlock {
  std::string target;  // "elastic.mu", "viscous.nu", "density"
  ParamSlot slot;
  bool log = false;
  double lower = 0, upper = 0;      // model units
  int offset = 0;                   // first entry in p
  int count = 0;                    // entries in p
  std::vector<int> entry;           // per element: index in [0, count), or −1 (not mapped)
  std::vector<std::string> labels;  // per entry, e.g. "elastic.mu[region 2]"
  Eigen::VectorXd initial;          // per entry, model units
  double scale = 1;                 // a linear block's typical size (FitParameterSpec::scale)
  bool per_element = false;
  /// Multiplier blocks: B (elements × count) and the field it scales, q⁰ per
  /// element (the model's at construction). Empty for value blocks.
  Eigen::MatrixXd basis;
  Eigen::VectorXd nominal;
  /// True for a block that reuses an earlier block's entries (offset, count).
  bool shares_entries = false;
  /// A Gaussian prior at 0 (FitParameterSpec::penalty): Φ gains penalty Σ (p/scale)².
  double penalty = 0;
  /// Body-force blocks (slot.is_force()): the field's knots over [0, force_end].
  int knots = 0;
  double force_end = 0;
  bool is_multiplier() const { return basis.size() > 0; }
};

/// Parameters of the observation (MarkerObjective's θ) rather than of the model:
/// `markers.clock_offset` (1 entry, s), `markers.<name>.offset` (3, m, rest frame),
/// `markers.registration` (6: rotation vector in rad, translation in m). Linear,
/// zero in the nominal model.
struct ObservationBlock {
  std::string target;
  int theta = 0;   // first entry in MarkerObjective's observation vector
  int count = 0;   // entries
  int offset = 0;  // first entry in p
  double lower = 0, upper = 0;
  double scale = 1;  // typical size (FitParameterSpec::scale)
  std::vector<std::string> labels;
  Eigen::VectorXd initial;
};

class ParameterMap {
 public:
  /// Builds the blocks of a `fit:` section for a model built from `scenario`;
  /// `observed_markers` are the objective's markers (MarkerObjective::names), which
  /// observation targets refer to.
  ParameterMap(const std::vector<FitParameterSpec>& specs, const Scenario& scenario,
               const FemModel& model, const std::vector<std::string>& observed_markers = {});

  int size() const { return size_; }
  const std::vector<ParameterBlock>& blocks() const { return blocks_; }
  std::vector<ParamSlot> slots() const;
  std::string label(int j) const;

  /// Optimiser-space start and bounds (log applied).
  Eigen::VectorXd initial() const;
  Eigen::VectorXd lower() const;
  Eigen::VectorXd upper() const;
  /// Per entry of p, the size of a unit step for the optimiser: 1 for log entries and
  /// multiplier coefficients, the block's typical size for linear ones (a stiffening
  /// modulus fitted from 0 moves in steps of the body's moduli, not of 1 Pa).
  Eigen::VectorXd units() const;
  /// Model value of entry j of p.
  double value(const Eigen::VectorXd& p, int j) const;
  bool is_log(int j) const { return block_of_[j] >= 0 && blocks_[block_of_[j]].log; }
  /// Entries of p that move the model (not observation entries), ascending: the
  /// ones forward sensitivities carry.
  std::vector<int> model_entries() const;
  /// Entries of p that fit.parameters[k] made (specs are laid out in order).
  std::vector<int> entries_of_spec(int k) const;
  /// The element block entry j belongs to (j must be a model entry).
  const ParameterBlock& block_of_entry(int j) const { return blocks_[block_of_[j]]; }
  /// dq/dp of entry j (q for log blocks, 1 otherwise).
  double derivative(const Eigen::VectorXd& p, int j) const;

  /// Writes q(p) into the model (material fields, density) and refreshes what
  /// depends on them (rest tangents, mass).
  void apply(const Eigen::VectorXd& p, FemModel& model) const;
  /// q of slot s in element e at p: the value block's entry (or the scenario's
  /// value) times the multipliers of that slot that map e.
  double element_value(const Eigen::VectorXd& p, int s, int e) const;
  /// Calls visit(j, ∂q/∂p_j) for every entry j of p that q of slot s in element e
  /// depends on (none when the block does not map e).
  template <class Visit>
  void for_each_dependency(const Eigen::VectorXd& p, int s, int e, Visit visit) const;
  /// Index in p of slot s in element e for a value block, or −1.
  int index(int s, int e) const;

  /// Pairs of entries of per-element blocks whose elements share a face: the
  /// neighbours of the smoothness regulariser.
  std::vector<std::pair<int, int>> neighbour_pairs(const Mesh& mesh) const;
  /// The priors' penalty Σ_blocks penalty Σⱼ (pⱼ/scale)², and its gradient added to g.
  double prior_penalty(const Eigen::VectorXd& p, Eigen::VectorXd* g = nullptr) const;
  /// True when some block carries a body-force field.
  bool has_body_force() const;

  const std::vector<ObservationBlock>& observation_blocks() const { return observation_blocks_; }
  /// θ from p: the observation entries set, the others zero (the nominal).
  Eigen::VectorXd observation_vector(const Eigen::VectorXd& p, int theta_size) const;
  /// gradient[j] += dΦ/dθ at j for the observation entries of p.
  void add_observation_gradient(const Eigen::VectorXd& dphi_dtheta,
                                Eigen::VectorXd& gradient) const;

 private:
  std::vector<ParameterBlock> blocks_;
  std::vector<ObservationBlock> observation_blocks_;
  std::vector<int> spec_begin_;  // per spec: its first entry of p
  std::vector<int> block_of_;    // per entry of p: its element block, or −1 − observation block
  /// Per block: the value block of its slot (−1: the scenario's value), and the
  /// multiplier blocks of its slot.
  std::vector<int> value_block_;
  std::vector<std::vector<int>> multipliers_;
  /// Π exp(B p) over the multipliers of block s's slot that map element e.
  double multiplier(const Eigen::VectorXd& p, int s, int e) const;
  int size_ = 0;
};

template <class Visit>
void ParameterMap::for_each_dependency(const Eigen::VectorXd& p, int s, int e, Visit visit) const {
  const ParameterBlock& b = blocks_[s];
  if (b.entry[e] < 0) return;
  if (!b.is_multiplier()) {
    const int j = b.offset + b.entry[e];
    visit(j, derivative(p, j) * multiplier(p, s, e));
    return;
  }
  const double q = element_value(p, s, e);
  for (int k = 0; k < b.count; ++k)
    if (const double w = b.basis(e, k); w != 0) visit(b.offset + k, q * w);
}

}  // namespace kelvin
