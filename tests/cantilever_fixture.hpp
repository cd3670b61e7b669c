#pragma once
// A slender cantilever (square bar clamped at x = 0) shared by the beam-theory and
// damping tests: geometry, material and the tip deflection measure.
#include <gtest/gtest.h>

#include <Eigen/CholmodSupport>
#include <cmath>
#include <memory>

#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"
#include "engine/mesh.hpp"
#include "engine/mesh_refine.hpp"
#include "engine/selection.hpp"
#include "engine/static_solver.hpp"

namespace kelvin::test {

// Slender square bar (L/h = 20: shear and rotary-inertia corrections < 0.3%).
constexpr double kLength = 0.2, kHeight = 0.01, kE = 1e8, kPoisson = 0.3, kRho = 1000, kG = 9.81;

struct Beam {
  Mesh mesh;
  std::unique_ptr<FemModel> model;
};

/// The bar with `cells_across` cells over its height, neo-Hookean with (E, ν) plus
/// optional extra terms (e.g. damping), under gravity −g e_z, its clamped end's
/// lower corner at `origin`; the box mesh refined `refine` times (engine/mesh_refine).
inline Beam make_beam(int cells_across, double gravity, std::vector<MaterialTerm> extra = {},
                      const Eigen::Vector3d& origin = Eigen::Vector3d::Zero(), int refine = 0) {
  Beam b;
  b.mesh =
      refine_uniformly(generate_box(origin, origin + Eigen::Vector3d(kLength, kHeight, kHeight),
                                    kHeight / cells_across),
                       refine);
  const double lambda = kE * kPoisson / ((1 + kPoisson) * (1 - 2 * kPoisson));
  const double mu = kE / (2 * (1 + kPoisson));
  const int ne = b.mesh.num_tets();
  std::vector<MaterialTerm> terms{
      {create_builtin_material("neo-hookean"), Eigen::Vector2d(lambda, mu).replicate(1, ne), {}}};
  for (auto& t : extra) {
    t.q = t.q.col(0).replicate(1, ne).eval();
    terms.push_back(std::move(t));
  }
  NodeSelection root;
  root.axis = 0;
  root.at = origin.x();
  b.model =
      std::make_unique<FemModel>(b.mesh, std::move(terms), Eigen::VectorXd::Constant(ne, kRho),
                                 Eigen::Vector3d(0, 0, -gravity),
                                 std::vector<ClampBinding>{{"root", select_nodes(b.mesh, root),
                                                            std::make_shared<FixedMotion>()}},
                                 true);
  return b;
}

/// Mean vertical displacement of the free end face (less sensitive to the local
/// mesh than a single node).
inline double tip_deflection(const Beam& b, const Eigen::VectorXd& x) {
  const double end = b.mesh.nodes.row(0).minCoeff() + kLength;
  double sum = 0;
  int count = 0;
  for (int a = 0; a < b.mesh.num_nodes(); ++a)
    if (std::abs(b.mesh.nodes(0, a) - end) < 1e-9) {
      sum += x[b.model->dof(a, 2)] - b.mesh.nodes(2, a);
      ++count;
    }
  return sum / count;
}

/// First bending frequency (Hz) of the Euler–Bernoulli cantilever.
inline double theory_frequency() {
  const double beta = 1.8751040687;  // first root of 1 + cos β cosh β = 0
  const double I = std::pow(kHeight, 4) / 12, A = kHeight * kHeight;
  return beta * beta / (2 * M_PI) * std::sqrt(kE * I / (kRho * A * std::pow(kLength, 4)));
}

/// Lowest eigenmode of K₀ φ = ω² M φ for the beam at rest, by inverse
/// iteration with a Cholesky factorisation of K₀ (the clamped bar is SPD). The two
/// first bending modes (y and z) coincide; the next mode is far above, so a few
/// tens of iterations converge to round-off.
struct Mode {
  double frequency;       // Hz
  Eigen::VectorXd shape;  // over the free dofs, M-normalised
};
inline Mode first_mode(const Beam& b) {
  Eigen::Matrix3Xd x = b.mesh.nodes, v = Eigen::Matrix3Xd::Zero(3, b.mesh.num_nodes());
  AssemblyRequest req;
  req.stiffness = true;
  AssemblyOutput out;
  EXPECT_TRUE(b.model->assemble(x, v, req, out));
  const Eigen::SparseMatrix<double> K = to_sparse_matrix(b.model->pattern(), out.K);
  const Eigen::SparseMatrix<double> M = to_sparse_matrix(b.model->pattern(), b.model->mass());
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> chol(K);
  EXPECT_EQ(chol.info(), Eigen::Success);
  Eigen::VectorXd phi = Eigen::VectorXd::Ones(K.rows()), next;
  double lambda = 0;
  for (int it = 0; it < 60; ++it) {
    next = chol.solve(M * phi);
    lambda = phi.dot(M * phi) / phi.dot(M * next);  // Rayleigh quotient of the pair
    phi = next / std::sqrt(next.dot(M * next));
  }
  lambda = phi.dot(K * phi) / phi.dot(M * phi);
  return {std::sqrt(lambda) / (2 * M_PI), phi};
}

struct FreeVibration {
  std::vector<double> t, tip, energy;
  std::vector<double> modal;  // φᵀ M (x − X) when a mode shape φ is given
};

/// Releases the beam from its static deflection under gravity with gravity then
/// switched off (undamped unless `damping` terms are given), sampling tip deflection and total
/// energy.
inline FreeVibration release(int cells_across, double duration, int samples, double rtol,
                             std::vector<MaterialTerm> damping = {},
                             const Eigen::VectorXd* mode = nullptr) {
  Beam loaded = make_beam(cells_across, kG);
  Eigen::VectorXd x0 = rigid_initial_guess(*loaded.model, 0.0);
  const StaticResult r = solve_static(*loaded.model, 0.0, x0);
  EXPECT_TRUE(r.converged) << r.message;
  Beam free = make_beam(cells_across, 0.0, std::move(damping));
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
    if (k > 0) {
      EXPECT_TRUE(ida.advance_to(t, duration)) << ida.error();
    }
    const Eigen::VectorXd& xs = k > 0 ? ida.positions() : x0;
    const Eigen::VectorXd& vs = k > 0 ? ida.velocities() : v0;
    free.model->expand(t, xs.data(), vs.data(), x, v);
    free.model->assemble(x, v, energy, asm_out);
    out.t.push_back(t);
    out.tip.push_back(tip_deflection(free, xs));
    if (mode) {
      Eigen::VectorXd u(xs.size()), Mu = Eigen::VectorXd::Zero(xs.size());
      Eigen::VectorXd X(xs.size());
      free.model->restrict(free.mesh.nodes, X.data());
      u = xs - X;
      free.model->mass_multiply(u.data(), Mu.data());
      out.modal.push_back(mode->dot(Mu));
    }
    out.energy.push_back(asm_out.energy + free.model->kinetic_energy(v));
  }
  return out;
}

/// Frequency from the mean spacing of the zero crossings of the tip deflection.
inline double crossing_frequency(const FreeVibration& fv) {
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

}  // namespace kelvin::test
