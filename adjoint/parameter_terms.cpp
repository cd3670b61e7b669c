#include "adjoint/parameter_terms.hpp"

#include <algorithm>

namespace kelvin {

SmoothnessTerm::SmoothnessTerm(const ParameterMap& map, const Mesh& mesh, double gamma)
    : pairs_(map.neighbour_pairs(mesh)), gamma_(gamma) {}

double SmoothnessTerm::roughness(const Eigen::VectorXd& p) const {
  double sum = 0;
  for (const auto& [a, b] : pairs_) sum += (p[a] - p[b]) * (p[a] - p[b]);
  return sum;
}

double SmoothnessTerm::value(const Eigen::VectorXd& p, Eigen::VectorXd* g) const {
  if (g)
    for (const auto& [a, b] : pairs_) {
      const double d = 2 * gamma_ * (p[a] - p[b]);
      (*g)[a] += d;
      (*g)[b] -= d;
    }
  return gamma_ * roughness(p);
}

double PriorTerm::value(const Eigen::VectorXd& p, Eigen::VectorXd* g) const {
  return map_.prior_penalty(p, g);
}

SplineSlopeTerm::SplineSlopeTerm(const ParameterMap& map, const FemModel& model, double weight)
    : map_(map), model_(model), weight_(weight) {
  const std::vector<ParamSlot> slots = map.slots();
  const auto& terms = model.terms();
  for (int t = 0; t < static_cast<int>(terms.size()); ++t) {
    if (terms[t].model->name() != "spline") continue;
    const auto& params = terms[t].model->params();
    for (int k = 0; k + 1 < static_cast<int>(params.size()); ++k) {
      // f1 … fK then h1 … hM: a pair within one curve has the same first letter.
      if (params[k].name[0] != params[k + 1].name[0]) continue;
      Knot a{t, k, {}}, b{t, k + 1, {}};
      for (int s = 0; s < static_cast<int>(slots.size()); ++s) {
        if (slots[s].term != t) continue;
        if (slots[s].index == k) a.slots.push_back(s);
        if (slots[s].index == k + 1) b.slots.push_back(s);
      }
      if (!a.slots.empty() || !b.slots.empty()) pairs_.emplace_back(a, b);
    }
  }
  const int ne = model.mesh().num_tets();
  volume_share_.resize(ne);
  for (int e = 0; e < ne; ++e) volume_share_[e] = model.elements()[e].volume;
  volume_share_ /= volume_share_.sum();
}

double SplineSlopeTerm::knot(const Knot& k, const Eigen::VectorXd& p, int e) const {
  // Any block of the knot gives its value (the value block's times the multipliers).
  return k.slots.empty() ? model_.terms()[k.term].q(k.index, e)
                         : map_.element_value(p, k.slots.front(), e);
}

double SplineSlopeTerm::value(const Eigen::VectorXd& p, Eigen::VectorXd* g) const {
  double sum = 0;
  for (const auto& [a, b] : pairs_)
    for (int e = 0; e < volume_share_.size(); ++e) {
      const double fall = std::min(0.0, knot(b, p, e) - knot(a, p, e));
      if (fall == 0) continue;
      const double w = weight_ * volume_share_[e];
      sum += w * fall * fall;
      if (!g) continue;
      // d(fall²)/dq_b = 2 fall, d/dq_a = −2 fall, through every block of each knot.
      for (int s : b.slots)
        map_.for_each_dependency(p, s, e, [&](int j, double dq) { (*g)[j] += 2 * w * fall * dq; });
      for (int s : a.slots)
        map_.for_each_dependency(p, s, e, [&](int j, double dq) { (*g)[j] -= 2 * w * fall * dq; });
    }
  return sum;
}

std::vector<std::unique_ptr<ParameterTerm>> parameter_terms(const ParameterMap& map,
                                                            const FemModel& model, double gamma,
                                                            double spline_slope_penalty) {
  std::vector<std::unique_ptr<ParameterTerm>> terms;
  if (gamma > 0) terms.push_back(std::make_unique<SmoothnessTerm>(map, model.mesh(), gamma));
  if (std::any_of(map.blocks().begin(), map.blocks().end(),
                  [](const ParameterBlock& b) { return b.penalty > 0; }))
    terms.push_back(std::make_unique<PriorTerm>(map));
  if (spline_slope_penalty > 0) {
    auto slopes = std::make_unique<SplineSlopeTerm>(map, model, spline_slope_penalty);
    if (slopes->pairs() > 0) terms.push_back(std::move(slopes));
  }
  return terms;
}

}  // namespace kelvin
