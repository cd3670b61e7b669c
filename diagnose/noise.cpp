#include "diagnose/noise.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

namespace kelvin {

NoiseEstimate estimate_noise(const Eigen::VectorXd& r, const std::vector<ResidualSample>& samples) {
  NoiseEstimate out;
  if (r.size() == 0) return out;
  out.naive = std::sqrt(r.squaredNorm() / static_cast<double>(r.size()));
  // One series per experiment, marker and axis, in time order.
  std::map<std::tuple<int, int, int>, std::vector<std::pair<double, double>>> series;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const ResidualSample& s = samples[k];
    series[{s.experiment, s.marker, s.axis}].emplace_back(s.t,
                                                          r[static_cast<long>(k)] / s.sqrt_weight);
  }
  std::vector<double> d3;
  for (auto& [key, v] : series) {
    std::sort(v.begin(), v.end());
    // Consecutive frames: three gaps equal to the series' median one (occlusions
    // break runs). The median, not the smallest: one odd gap (the silicone beam's
    // release at t = 0, 3.7 ms before its first 100 Hz frame) left no run at all.
    if (v.size() < 4) continue;
    std::vector<double> gaps;
    for (std::size_t k = 1; k < v.size(); ++k) gaps.push_back(v[k].first - v[k - 1].first);
    std::nth_element(gaps.begin(), gaps.begin() + static_cast<long>(gaps.size() / 2), gaps.end());
    const double dt = gaps[gaps.size() / 2];
    const auto regular = [&](std::size_t k) {
      return std::abs(v[k].first - v[k - 1].first - dt) <= 0.01 * dt;
    };
    for (std::size_t k = 3; k < v.size(); ++k) {
      if (!regular(k) || !regular(k - 1) || !regular(k - 2)) continue;
      d3.push_back(
          std::abs(v[k].second - 3 * v[k - 1].second + 3 * v[k - 2].second - v[k - 3].second));
    }
  }
  out.differences = static_cast<int>(d3.size());
  if (d3.empty()) {
    out.sigma = out.naive;
    return out;
  }
  auto mid = d3.begin() + static_cast<long>(d3.size() / 2);
  std::nth_element(d3.begin(), mid, d3.end());
  out.sigma = 1.4826 * *mid / std::sqrt(20.0);
  return out;
}

}  // namespace kelvin
