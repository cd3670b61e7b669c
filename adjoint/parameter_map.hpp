#pragma once
/// \file
/// The parameter map turns the optimiser's vector p into model quantities: each
/// block names one slot (a material parameter or the density) and assigns every
/// element one entry of p (global: all the same; per region; per element), with
/// q = exp(p) for log-transformed blocks, so that dΦ/dp = q dΦ/dq there.
/// Gradients are computed per element and slot (dΦ/dq_e) and pulled back here.
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
  bool per_element = false;
};

class ParameterMap {
 public:
  /// Builds the blocks of a `fit:` section for a model built from `scenario`.
  ParameterMap(const std::vector<FitParameterSpec>& specs, const Scenario& scenario,
               const FemModel& model);

  int size() const { return size_; }
  const std::vector<ParameterBlock>& blocks() const { return blocks_; }
  std::vector<ParamSlot> slots() const;
  std::string label(int j) const;

  /// Optimiser-space start and bounds (log applied).
  Eigen::VectorXd initial() const;
  Eigen::VectorXd lower() const;
  Eigen::VectorXd upper() const;
  /// Model value of entry j of p.
  double value(const Eigen::VectorXd& p, int j) const;
  bool is_log(int j) const { return blocks_[block_of_[j]].log; }
  /// dq/dp of entry j (q for log blocks, 1 otherwise).
  double derivative(const Eigen::VectorXd& p, int j) const;

  /// Writes q(p) into the model (material fields, density) and refreshes what
  /// depends on them (rest tangents, mass).
  void apply(const Eigen::VectorXd& p, FemModel& model) const;
  /// Index in p of slot s in element e, or −1.
  int index(int s, int e) const;
  /// dΦ/dp from dΦ/dq per slot and element (slots × elements).
  Eigen::VectorXd pull_back(const Eigen::VectorXd& p, const Eigen::MatrixXd& dphi_dq) const;

  /// Pairs of entries of per-element blocks whose elements share a face: the
  /// neighbours of the smoothness regulariser.
  std::vector<std::pair<int, int>> neighbour_pairs(const Mesh& mesh) const;

 private:
  std::vector<ParameterBlock> blocks_;
  std::vector<int> block_of_;  // per entry of p
  int size_ = 0;
};

}  // namespace kelvin
