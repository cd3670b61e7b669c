#pragma once
/// \file
/// C2 cubic splines through sampled data, in slope form: the spline is the cubic
/// Hermite curve between consecutive knots with the slopes returned here. Used for
/// measured clamp motion and for captured marker tracks.
#include <Eigen/Core>
#include <array>
#include <vector>

namespace kelvin {

/// How the two end conditions of a spline are closed.
enum class SplineEnds {
  /// Zero second derivative at both ends: a clamp motion that starts and ends at rest.
  kNatural,
  /// Third derivative continuous across the second and the second-to-last knots
  /// (de Boor): reproduces any cubic exactly, so the ends are as accurate as the
  /// interior (O(h⁴)). Two knots give the secant, three the parabola.
  kNotAKnot,
};

/// Slopes at the knots `t` (increasing, at least 2) of the C2 cubic spline through
/// the columns of `y` (one row per component, one column per knot).
Eigen::MatrixXd cubic_spline_slopes(const std::vector<double>& t,
                                    const Eigen::Ref<const Eigen::MatrixXd>& y, SplineEnds ends);

/// Weights of (y₀, m₀, y₁, m₁) in the `derivative`-th time derivative (0, 1 or 2) of
/// the cubic Hermite curve with end values y₀, y₁ and end slopes m₀, m₁ over an
/// interval of length h, at the fraction s ∈ [0, 1] of it.
std::array<double, 4> hermite_weights(double s, double h, int derivative);

/// That derivative itself, for column vectors (knot values and slopes of a spline).
template <typename Y, typename M>
typename Y::PlainObject hermite(const Y& y0, const M& m0, const Y& y1, const M& m1, double s,
                                double h, int derivative) {
  const std::array<double, 4> w = hermite_weights(s, h, derivative);
  return w[0] * y0 + w[1] * m0 + w[2] * y1 + w[3] * m1;
}

}  // namespace kelvin
