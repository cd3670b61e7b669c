#include "diagnose/ranking.hpp"

#include <algorithm>
#include <cmath>

namespace kelvin {
namespace {

/// How far a score clears its threshold, in units of the threshold: comparable
/// across candidates of different degrees of freedom.
double margin(const CandidateScore& s, double threshold) {
  return s.error.empty() && s.dof > 0 ? (s.statistic - threshold) / threshold : -HUGE_VAL;
}

}  // namespace

Ranking rank_candidates(const Eigen::VectorXd& r, const Eigen::MatrixXd& J,
                        const std::vector<int>& nominal,
                        const std::vector<std::pair<std::string, std::vector<int>>>& groups,
                        const ScreeningOptions& options, double alpha) {
  Ranking out;
  out.alpha = alpha;
  const int m = static_cast<int>(groups.size());
  if (m == 0) return out;
  const std::vector<CandidateScore> marginal = score_candidates(r, J, nominal, groups, options);
  const auto threshold = [&](const CandidateScore& s) {
    return chi_square_quantile(alpha / m, std::max(1, s.dof));
  };

  std::vector<int> conditioning = nominal, remaining(m);
  for (int k = 0; k < m; ++k) remaining[k] = k;
  bool significant_left = true;
  while (!remaining.empty()) {
    std::vector<std::pair<std::string, std::vector<int>>> rest;
    for (int k : remaining) rest.push_back(groups[k]);
    const std::vector<CandidateScore> scores = score_candidates(r, J, conditioning, rest, options);
    int best = 0;
    for (int k = 1; k < static_cast<int>(remaining.size()); ++k)
      if (margin(scores[k], threshold(scores[k])) > margin(scores[best], threshold(scores[best])))
        best = k;
    RankedCandidate rc;
    rc.candidate = remaining[best];
    rc.marginal = marginal[rc.candidate];
    rc.conditional = scores[best];
    rc.threshold = threshold(rc.conditional);
    rc.significant = significant_left && margin(rc.conditional, rc.threshold) > 0 &&
                     margin(rc.marginal, threshold(rc.marginal)) > 0;
    // Later candidates are scored against the significant ones only.
    if (rc.significant)
      conditioning.insert(conditioning.end(), rc.conditional.active.begin(),
                          rc.conditional.active.end());
    else
      significant_left = false;
    out.order.push_back(rc);
    remaining.erase(remaining.begin() + best);
  }

  // Confounded pairs among the candidates that clear the threshold on their own.
  std::vector<int> strong;
  for (int k = 0; k < m; ++k)
    if (margin(marginal[k], threshold(marginal[k])) > 0) strong.push_back(k);
  for (std::size_t i = 0; i < strong.size(); ++i)
    for (std::size_t j = i + 1; j < strong.size(); ++j) {
      const auto& a = marginal[strong[i]].active;
      const auto& b = marginal[strong[j]].active;
      if (a.empty() || b.empty()) continue;
      const double c = confounding(J, nominal, a, b);
      if (c > kConfoundedCorrelation) out.confounded.push_back({strong[i], strong[j], c});
    }
  return out;
}

}  // namespace kelvin
