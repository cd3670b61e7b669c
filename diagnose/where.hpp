#pragma once
/// \file
/// Where the residual of a fitted model lies: per marker and axis, per time window,
/// per frequency band (against the observed signal's spectrum), per region of the
/// body, and per marker the gain and delay of the simulated track against the
/// observed one (a timing error shows as a delay at unit gain, a damping or
/// stiffness error as a gain and a delay that change with frequency).
#include <Eigen/Core>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "adjoint/uncertainty.hpp"
#include "diagnose/candidates.hpp"

namespace kelvin {

struct MarkerResidual {
  std::string name, region;
  double along = 0;                               // 0 at the clamp, 1 at the free end
  Eigen::Vector3d rms = Eigen::Vector3d::Zero();  // per axis (m)
  double rms_total = 0;                           // per coordinate (m)
  double excess = 0;           // sqrt(max(0, rms² − σ²)): the model's part (m)
  double gain = 1, delay = 0;  // observed ≈ gain · simulated(t − delay), main axis
  int main_axis = 0;           // the axis with the largest observed motion
  int samples = 0;
};
struct WindowResidual {
  double t0 = 0, t1 = 0, rms = 0;
};
struct BandResidual {
  double f0 = 0, f1 = 0;
  double residual_fraction = 0, signal_fraction = 0;  // of the total power
};
struct RegionResidual {
  std::string name;
  double rms = 0, excess = 0;
  std::vector<std::string> markers;
};
struct ResidualTables {
  std::vector<MarkerResidual> markers;
  std::vector<WindowResidual> windows;
  std::vector<BandResidual> bands;
  std::vector<RegionResidual> regions;
};

/// A marker's position in the rest mesh (where its embedding puts it).
Eigen::Vector3d rest_position(const Mesh& mesh, const MarkerEmbedding& marker);

/// The region of the body at `along` (0 clamp … 1 free end): clamp zone, middle,
/// free end (thirds).
std::string region_of(double along);

/// Tables of the training experiment 0's residual r (samples as from
/// gauss_newton_system) given the noise level σ.
ResidualTables locate_residual(FitProblem& problem, const Eigen::VectorXd& residual,
                               const std::vector<ResidualSample>& samples, const BodyAxis& axis,
                               double sigma);

}  // namespace kelvin
