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

using namespace kelvin;

namespace {

// Slender square bar (L/h = 20: shear and rotary-inertia corrections < 0.3%).
constexpr double kLength = 0.2, kHeight = 0.01, kE = 1e8, kPoisson = 0.3, kRho = 1000, kG = 9.81;

struct Beam {
  Mesh mesh;
  std::unique_ptr<FemModel> model;
  int tip_node = -1;  // a node on the neutral axis at the free end... or nearest
};

Beam make_beam(int cells_across, double gravity) {
  Beam b;
  b.mesh = generate_box({0, 0, 0}, {kLength, kHeight, kHeight}, kHeight / cells_across);
  const double lambda = kE * kPoisson / ((1 + kPoisson) * (1 - 2 * kPoisson));
  const double mu = kE / (2 * (1 + kPoisson));
  const int ne = b.mesh.num_tets();
  std::vector<MaterialTerm> terms{
      {create_builtin_material("neo-hookean"), Eigen::Vector2d(lambda, mu).replicate(1, ne)}};
  NodeSelection root;
  root.axis = 0;
  root.at = 0;
  b.model = std::make_unique<FemModel>(b.mesh, std::move(terms), Eigen::VectorXd::Constant(ne, kRho),
                                       Eigen::Vector3d(0, 0, -gravity),
                                       std::vector<ClampBinding>{{"root", select_nodes(b.mesh, root),
                                                                  std::make_shared<FixedMotion>()}},
                                       true);
  double best = INFINITY;
  for (int a = 0; a < b.mesh.num_nodes(); ++a) {
    const double d = (b.mesh.nodes.col(a) - Eigen::Vector3d(kLength, kHeight / 2, kHeight / 2)).norm();
    if (d < best) best = d, b.tip_node = a;
  }
  return b;
}

/// Mean vertical displacement of the free end face (less sensitive to the local
/// mesh than a single node).
double tip_deflection(const Beam& b, const Eigen::VectorXd& x) {
  double sum = 0;
  int count = 0;
  for (int a = 0; a < b.mesh.num_nodes(); ++a)
    if (std::abs(b.mesh.nodes(0, a) - kLength) < 1e-12) {
      sum += x[b.model->dof(a, 2)] - b.mesh.nodes(2, a);
      ++count;
    }
  return sum / count;
}

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
  const Richardson R = extrapolate(h, w);
  std::printf("  observed order %.2f, Richardson-extrapolated deflection %.6e (%.2f%% from theory)\n",
              R.order, R.limit, 100 * (R.limit / theory - 1));
  EXPECT_NEAR(R.limit, theory, 0.02 * theory);
}

namespace {

struct FreeVibration {
  std::vector<double> t, tip, energy;
};

/// Releases the beam from its static deflection under gravity with gravity then
/// switched off (undamped), sampling tip deflection and total energy.
FreeVibration release(int cells_across, double duration, int samples, double rtol) {
  Beam loaded = make_beam(cells_across, kG);
  Eigen::VectorXd x0 = rigid_initial_guess(*loaded.model, 0.0);
  const StaticResult r = solve_static(*loaded.model, 0.0, x0);
  EXPECT_TRUE(r.converged) << r.message;
  Beam free = make_beam(cells_across, 0.0);
  IntegratorOptions opt;
  opt.rtol = rtol;
  opt.atol = 1e-12;
  opt.velocity_atol_scale = 100;
  IdasIntegrator ida(*free.model, opt);
  const Eigen::VectorXd v0 = Eigen::VectorXd::Zero(x0.size());
  ida.initialize(0.0, x0, v0);
  FreeVibration out;
  Eigen::Matrix3Xd x, v;
  AssemblyOutput asm_out;
  AssemblyRequest energy;
  energy.force = false;
  energy.energy = true;
  for (int k = 0; k <= samples; ++k) {
    const double t = duration * k / samples;
    if (k > 0) EXPECT_TRUE(ida.advance_to(t, duration)) << ida.error();
    const Eigen::VectorXd& xs = k > 0 ? ida.positions() : x0;
    const Eigen::VectorXd& vs = k > 0 ? ida.velocities() : v0;
    free.model->expand(t, xs.data(), vs.data(), x, v);
    free.model->assemble(x, v, energy, asm_out);
    out.t.push_back(t);
    out.tip.push_back(tip_deflection(free, xs));
    out.energy.push_back(asm_out.energy + free.model->kinetic_energy(v));
  }
  return out;
}

/// Frequency from the mean spacing of the zero crossings of the tip deflection.
double crossing_frequency(const FreeVibration& fv) {
  std::vector<double> crossings;
  for (size_t k = 1; k < fv.t.size(); ++k)
    if ((fv.tip[k - 1] < 0) != (fv.tip[k] < 0)) {
      const double s = fv.tip[k - 1] / (fv.tip[k - 1] - fv.tip[k]);
      crossings.push_back(fv.t[k - 1] + s * (fv.t[k] - fv.t[k - 1]));
    }
  EXPECT_GE(crossings.size(), 4u);
  const double half_period = (crossings.back() - crossings.front()) / (crossings.size() - 1);
  return 1.0 / (2 * half_period);
}

double theory_frequency() {
  const double beta = 1.8751040687;  // first root of 1 + cos β cosh β = 0
  const double I = std::pow(kHeight, 4) / 12, A = kHeight * kHeight;
  return beta * beta / (2 * M_PI) * std::sqrt(kE * I / (kRho * A * std::pow(kLength, 4)));
}

}  // namespace

TEST(Cantilever, FirstBendingFrequencyConvergesToEulerBernoulli) {
  const double f_theory = theory_frequency();
  const int cells[3] = {2, 3, 4};
  double h[3], f[3];
  for (int k = 0; k < 3; ++k) {
    // About 3.5 periods of the coarse mesh, sampled 60 times per period.
    const FreeVibration fv = release(cells[k], 3.5 / f_theory, 240, 1e-7);
    h[k] = kHeight / cells[k];
    f[k] = crossing_frequency(fv);
    std::printf("  %d cells across: first bending frequency %.5f Hz (theory %.5f, ratio %.4f)\n",
                cells[k], f[k], f_theory, f[k] / f_theory);
  }
  EXPECT_LT(std::abs(f[2] - f_theory), std::abs(f[0] - f_theory));
  const Richardson R = extrapolate(h, f);
  std::printf("  observed order %.2f, Richardson-extrapolated frequency %.5f Hz (%.2f%% from theory)\n",
              R.order, R.limit, 100 * (R.limit / f_theory - 1));
  EXPECT_NEAR(R.limit, f_theory, 0.03 * f_theory);
}

TEST(Cantilever, UndampedEnergyIsConservedOverTwentyPeriods) {
  const double period = 1.0 / theory_frequency();
  const FreeVibration fv = release(2, 20 * period, 400, 1e-8);
  double drift = 0;
  for (double e : fv.energy) drift = std::max(drift, std::abs(e - fv.energy[0]) / fv.energy[0]);
  std::printf("  max relative energy drift over 20 periods at rtol 1e-8: %.3e\n", drift);
  EXPECT_LT(drift, 1e-4);
}
