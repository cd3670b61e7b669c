// Cantilever beam against Euler–Bernoulli theory: static tip deflection under
// gravity and the first bending frequency of free vibration, each converged over
// three meshes and Richardson-extrapolated; energy conservation of the integrator.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"
#include "engine/mesh.hpp"
#include "engine/selection.hpp"
#include "engine/static_solver.hpp"
#include "tests/cantilever_fixture.hpp"

using namespace kelvin;
using namespace kelvin::test;

namespace {

struct Richardson {
  double order, limit;
};
/// f(h) = f∞ + C h^p from three meshes with arbitrary ratios: p by bisection on
/// (f₁ − f₂)/(f₂ − f₃) = (h₁^p − h₂^p)/(h₂^p − h₃^p).
Richardson extrapolate(const double h[3], const double f[3]) {
  const double target = (f[0] - f[1]) / (f[1] - f[2]);
  auto ratio = [&](double p) {
    return (std::pow(h[0], p) - std::pow(h[1], p)) / (std::pow(h[1], p) - std::pow(h[2], p));
  };
  double lo = 0.1, hi = 8;
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    (ratio(mid) < target ? lo : hi) = mid;
  }
  const double p = 0.5 * (lo + hi);
  const double C = (f[1] - f[2]) / (std::pow(h[1], p) - std::pow(h[2], p));
  return {p, f[2] - C * std::pow(h[2], p)};
}

/// Limit of f(h) = f∞ + C h² from the two finest of three meshes (with the observed
/// order of all three). Linear tets lock
/// in bending: on 2–8 cells across the error is pre-asymptotic (the observed order
/// of the three meshes is printed, and rises toward 2 as the mesh refines), so the
/// asymptotic order p = 2 of linear elements is used.
Richardson extrapolate_p2(const double h[3], const double f[3], const char* what, double theory) {
  const Richardson observed = extrapolate(h, f);
  const double limit = f[2] + (f[2] - f[1]) / (std::pow(h[1] / h[2], 2) - 1);
  std::printf(
      "  observed order %.2f over the three meshes; Richardson (p = 2) %s %.6e (%.2f%% "
      "from theory)\n",
      observed.order, what, limit, 100 * (limit / theory - 1));
  return {observed.order, limit};
}

}  // namespace

TEST(Cantilever, StaticTipDeflectionConvergesToEulerBernoulli) {
  // w = q L⁴ / (8 E I), q = ρ g A, I = h⁴/12.
  const double I = std::pow(kHeight, 4) / 12, q = kRho * kG * kHeight * kHeight;
  const double theory = q * std::pow(kLength, 4) / (8 * kE * I);
  const int cells[3] = {2, 4, 8};
  double h[3], w[3];
  for (int k = 0; k < 3; ++k) {
    Beam b = make_beam(cells[k], kG);
    Eigen::VectorXd x = rigid_initial_guess(*b.model, 0.0);
    const StaticResult r = solve_static(*b.model, 0.0, x);
    ASSERT_TRUE(r.converged) << r.message;
    h[k] = kHeight / cells[k];
    w[k] = -tip_deflection(b, x);
    std::printf("  %d cells across (%d tets): tip deflection %.6e m (theory %.6e, ratio %.4f)\n",
                cells[k], b.mesh.num_tets(), w[k], theory, w[k] / theory);
  }
  EXPECT_LT(std::abs(w[0] - theory), 1.0 * theory);
  EXPECT_LT(std::abs(w[2] - theory), std::abs(w[1] - theory));  // converges toward theory
  EXPECT_LT(std::abs(w[1] - theory), std::abs(w[0] - theory));
  const Richardson R = extrapolate_p2(h, w, "deflection", theory);
  EXPECT_GT(R.order, 0.5);
  EXPECT_NEAR(R.limit, theory, 0.02 * theory);
}

// Uniform refinement nests the finite-element spaces: the work of gravity at
// equilibrium (the compliance, for this nearly linear sag) can only grow from one
// level to the next, and the tip deflection converges to beam theory.
TEST(Cantilever, RefinedMeshesConvergeMonotonicallyToEulerBernoulli) {
  const double I = std::pow(kHeight, 4) / 12, q = kRho * kG * kHeight * kHeight;
  const double theory = q * std::pow(kLength, 4) / (8 * kE * I);
  double h[3], w[3], work[3];
  for (int level = 0; level < 3; ++level) {
    Beam b = make_beam(2, kG, {}, Eigen::Vector3d::Zero(), level);
    Eigen::VectorXd x = rigid_initial_guess(*b.model, 0.0);
    const StaticResult r = solve_static(*b.model, 0.0, x);
    ASSERT_TRUE(r.converged) << r.message;
    work[level] = 0;
    for (int e = 0; e < b.mesh.num_tets(); ++e)
      for (int a = 0; a < 4; ++a) {
        const int node = b.mesh.tets(a, e);
        if (b.model->dof(node, 2) >= 0)
          work[level] -= kRho * tet_volume(b.mesh, e) / 4 * kG *
                         (x[b.model->dof(node, 2)] - b.mesh.nodes(2, node));
      }
    h[level] = kHeight / 2 / std::pow(2, level);
    w[level] = -tip_deflection(b, x);
    std::printf("  refined %d× (%d tets): tip deflection %.6e m (theory %.6e), work %.6e J\n",
                level, b.mesh.num_tets(), w[level], theory, work[level]);
  }
  EXPECT_GT(work[1], work[0]);
  EXPECT_GT(work[2], work[1]);
  // Linear tetrahedra lock in bending: on these meshes the error is pre-asymptotic
  // (observed order 0.9), and each level gains more than the one before it.
  const double e[3] = {theory - w[0], theory - w[1], theory - w[2]};
  EXPECT_GT(e[2], 0);
  EXPECT_GT(e[1] / e[2], e[0] / e[1]);
  EXPECT_GT(extrapolate_p2(h, w, "deflection", theory).order, 0.5);
}

TEST(Cantilever, FreeVibrationMatchesTheModalFrequencyOfTheMesh) {
  // Time integration against the eigenfrequency of the same discrete model: what
  // IDAS adds (phase error) must be small against the discretisation error.
  const double f_theory = theory_frequency();
  const double f_modal = first_mode(make_beam(2, 0.0)).frequency;
  const double f_dynamic = crossing_frequency(release(2, 3.5 / f_theory, 240, 1e-7));
  std::printf("  2 cells across: released free vibration %.5f Hz, modal %.5f Hz (%.3f%% apart)\n",
              f_dynamic, f_modal, 100 * (f_dynamic / f_modal - 1));
  EXPECT_NEAR(f_dynamic, f_modal, 0.005 * f_modal);
}

TEST(Cantilever, FirstBendingFrequencyConvergesToEulerBernoulli) {
  const double f_theory = theory_frequency();
  const int cells[3] = {2, 4, 8};
  double h[3], f[3];
  for (int k = 0; k < 3; ++k) {
    h[k] = kHeight / cells[k];
    f[k] = first_mode(make_beam(cells[k], 0.0)).frequency;
    std::printf("  %d cells across: first bending frequency %.5f Hz (theory %.5f, ratio %.4f)\n",
                cells[k], f[k], f_theory, f[k] / f_theory);
  }
  EXPECT_LT(std::abs(f[2] - f_theory), std::abs(f[1] - f_theory));
  EXPECT_LT(std::abs(f[1] - f_theory), std::abs(f[0] - f_theory));
  EXPECT_NEAR(extrapolate_p2(h, f, "frequency", f_theory).limit, f_theory, 0.03 * f_theory);
}

/// Largest relative change of the total energy of the released, undamped beam.
double energy_drift(int periods) {
  const FreeVibration fv = release(2, periods / theory_frequency(), 20 * periods, 1e-8);
  double drift = 0;
  for (double e : fv.energy) drift = std::max(drift, std::abs(e - fv.energy[0]) / fv.energy[0]);
  std::printf("  max relative energy drift over %d periods at rtol 1e-8: %.3e\n", periods, drift);
  return drift;
}

TEST(Cantilever, UndampedEnergyIsConservedOverFivePeriods) {
  EXPECT_LT(energy_drift(5), 1e-4);
}

// The same over twenty periods (label long: four minutes).
TEST(CantileverLong, UndampedEnergyIsConservedOverTwentyPeriods) {
  EXPECT_LT(energy_drift(20), 1e-4);
}
