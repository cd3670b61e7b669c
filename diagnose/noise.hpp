#pragma once
/// \file
/// The capture noise level from the residual of a model that may be wrong. The
/// residual of a nominal fit is not white where the model misses an effect, so
/// ‖r‖²/(N − n) overstates the noise by the gap itself. Third differences of each
/// marker coordinate over consecutive frames cancel a smooth model error (a few Hz
/// against a 180 Hz capture: (2π f Δt)³ ≈ 10⁻³ of it) and leave 20σ² of white
/// noise; their median absolute value, scaled by 1.4826/√20, ignores the few
/// places where the error is fast (a snap, an occlusion edge).
#include <Eigen/Core>
#include <vector>

#include "adjoint/uncertainty.hpp"

namespace kelvin {

struct NoiseEstimate {
  double sigma = 0;     // per coordinate (m)
  int differences = 0;  // third differences it rests on
  double naive = 0;     // sqrt(‖r‖² / N), for comparison (m)
};

NoiseEstimate estimate_noise(const Eigen::VectorXd& residual,
                             const std::vector<ResidualSample>& samples);

}  // namespace kelvin
