#include "diagnose/heldout_prediction.hpp"

#include <algorithm>
#include <cmath>

namespace kelvin {

double predicted_heldout_drop(const Eigen::VectorXd& h, const Eigen::MatrixXd& J,
                              const CandidateScore& s, const std::vector<int>& fitted) {
  if (!s.error.empty() || s.step.size() != static_cast<long>(s.active.size()) || s.step.size() == 0)
    return 0;
  Eigen::VectorXd moved = h;
  for (std::size_t k = 0; k < s.active.size(); ++k)
    moved += J.col(s.active[k]) * s.step[static_cast<long>(k)];
  if (s.fitted_step.size() == static_cast<long>(fitted.size()))
    for (std::size_t k = 0; k < fitted.size(); ++k)
      moved += J.col(fitted[k]) * s.fitted_step[static_cast<long>(k)];
  return h.squaredNorm() - moved.squaredNorm();
}

std::vector<int> order_by_heldout(const std::vector<int>& candidates,
                                  const std::vector<double>& drop) {
  std::vector<int> out = candidates;
  std::stable_sort(out.begin(), out.end(), [&](int a, int b) {
    const bool pa = std::isfinite(drop[a]), pb = std::isfinite(drop[b]);
    if (pa != pb) return pa;
    return pa && drop[a] > drop[b];
  });
  return out;
}

}  // namespace kelvin
