#include "engine/static_solver.hpp"

#include <fmt/format.h>

#include <Eigen/CholmodSupport>
#include <Eigen/KLUSupport>
#include <algorithm>
#include <cmath>

namespace kelvin {
namespace {

struct Residual {
  const FemModel& model;
  double t;
  double load_fraction;
  Eigen::Matrix3Xd x, v;
  AssemblyOutput out;
  Eigen::VectorXd pull;

  /// r(x) − s f_ext, and the potential energy W(x) − s f_ext·x when `energy`;
  /// false when an element is inadmissible at x.
  bool eval(const Eigen::VectorXd& xf, double s, bool tangent, Eigen::VectorXd& g,
            double* energy = nullptr) {
    model.expand(t, xf.data(), nullptr, x, v, s * load_fraction);
    AssemblyRequest req;
    req.stiffness = tangent;
    req.energy = energy != nullptr;
    if (!model.assemble(x, v, req, out)) return false;
    // A compliant clamp's pull holds the body at every load step: it is a support,
    // not a load.
    model.clamp_pull(t, false, pull);
    g = out.force - pull - s * load_fraction * model.external_force();
    if (energy)
      *energy = out.energy + model.clamp_spring_energy(t, x) -
                s * load_fraction * model.external_force().dot(xf);
    return true;
  }
};

}  // namespace

Eigen::VectorXd rigid_initial_guess(const FemModel& model, double t) {
  Eigen::VectorXd x(model.num_dofs());
  // A pressed probe (a ramped clamp) is a load, not the support.
  RigidPose pose;
  for (const auto& c : model.clamps())
    if (!c.ramped) {
      pose = c.motion->at(t);
      break;
    }
  Eigen::Matrix3Xd moved(3, model.mesh().num_nodes());
  for (int a = 0; a < moved.cols(); ++a) moved.col(a) = pose.position(model.mesh().nodes.col(a));
  model.restrict(moved, x.data());
  return x;
}

StaticResult solve_static(const FemModel& model, double t, Eigen::VectorXd& x_free,
                          const StaticOptions& opt) {
  StaticResult res;
  Residual R{model, t, opt.load_fraction, {}, {}, {}, {}};
  Eigen::VectorXd g, g_trial, x_trial;
  // A pressed probe (ramped clamp) may invert the start at its full depth: the start
  // must then be admissible with the probe at rest, and the load steps bring it in.
  const bool pressed = std::any_of(model.clamps().begin(), model.clamps().end(),
                                   [](const ClampBinding& c) { return c.ramped; });
  double imbalance = 0;
  // True while the force scale lacks the press's share: the start was checked at rest.
  bool scale_from_press = false;
  if (R.eval(x_free, 1.0, false, g)) {
    imbalance = g.norm();
  } else if (!pressed || !R.eval(x_free, 0.0, false, g)) {
    res.message =
        fmt::format("element {} is inverted in the starting configuration", R.out.failed_element);
    return res;
  } else {
    imbalance = g.norm();
    scale_from_press = true;
  }
  // Forces are compared to the load, or to the initial imbalance when there is no load.
  double scale = std::max({opt.load_fraction * model.external_force().norm(), imbalance, 1e-300});
  // Newton corrections below this length (1e-12 of the body's size) are round-off.
  const Eigen::Matrix3Xd& X = model.mesh().nodes;
  const double negligible = 1e-12 * (X.rowwise().maxCoeff() - X.rowwise().minCoeff()).norm();
  bool hyperelastic = true;  // every term has an energy (viscous terms vanish at rest)
  for (const auto& term : model.terms())
    hyperelastic &= term.model->is_viscous() || term.model->has_energy();
  Eigen::KLU<Eigen::SparseMatrix<double>> klu;
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> cholesky;
  // An indefinite K is expected far from equilibrium and handled below (KLU);
  // CHOLMOD would print a warning to stderr for each one.
  cholesky.cholmod().print = 0;
  bool analysed = false;

  // Load stepping: try the full load; on failure halve the increment.
  double s = 0, ds = 1;
  Eigen::VectorXd x_good = x_free;
  while (s < 1) {
    const double target = std::min(1.0, s + ds);
    Eigen::VectorXd x = x_good;
    bool ok = false;
    for (int it = 0; it < opt.max_iterations; ++it) {
      double pi0 = 0;  // potential energy at x, for the line search
      if (!R.eval(x, target, true, g, hyperelastic ? &pi0 : nullptr)) break;
      if (scale_from_press && it == 0) {
        // From the last equilibrium the imbalance is the press's increment alone:
        // scaled to its full depth, it is the force the press brings.
        scale = std::max(scale, g.norm() / (target - s));
        scale_from_press = false;
      }
      res.residual = g.norm() / scale;
      if (res.residual <= opt.tolerance) {
        ok = true;
        break;
      }
      ++res.iterations;
      const Eigen::SparseMatrix<double> K = to_sparse_matrix(model.pattern(), R.out.K);
      // K is symmetric, and positive definite near a stable equilibrium: supernodal
      // Cholesky (CHOLMOD) is far cheaper than LU on 3-D meshes. Where it is not
      // definite (buckling, far from equilibrium), LU (KLU) takes over.
      Eigen::VectorXd dx;
      if (!analysed) {
        cholesky.analyzePattern(K);
        klu.analyzePattern(K);
        analysed = true;
      }
      cholesky.factorize(K);
      if (cholesky.info() == Eigen::Success) {
        dx = cholesky.solve(-g);
      } else {
        klu.factorize(K);
        if (klu.info() != Eigen::Success) break;
        dx = klu.solve(-g);
      }
      if (dx.lpNorm<Eigen::Infinity>() <= negligible) {
        ok = true;
        break;
      }
      // Backtracking: on the potential energy (Armijo) when the model has one and dx
      // descends — a residual-norm search stalls on large rotations, where the
      // linearised step stretches fibres; otherwise on the residual norm.
      // Inadmissible trial states count as worse.
      double alpha = 1, pi_trial = 0;
      const double g0 = g.norm(), slope = g.dot(dx);
      const bool by_energy = hyperelastic && slope < 0;
      bool accepted = false;
      for (int ls = 0; ls < 30 && !accepted; ++ls, alpha *= 0.5) {
        x_trial = x + alpha * dx;
        if (by_energy)
          accepted = R.eval(x_trial, target, false, g_trial, &pi_trial) &&
                     pi_trial <= pi0 + 1e-4 * alpha * slope;
        else
          accepted =
              R.eval(x_trial, target, false, g_trial) && g_trial.norm() <= (1 - 1e-4 * alpha) * g0;
      }
      if (!accepted) {
        // At round-off level the residual norm cannot decrease any more.
        if (res.residual <= 1e3 * opt.tolerance) ok = true;
        break;
      }
      x = x_trial;
    }
    if (ok) {
      s = target;
      x_good = x;
      ++res.load_steps;
      ds = std::min(2 * ds, 1.0);
    } else {
      ds *= 0.5;
      if (ds < 1.0 / opt.max_load_steps) {
        res.message = fmt::format(
            "static equilibrium not found: Newton failed at {:.1f}% of the load (relative "
            "residual {:.3g})",
            100 * std::min(1.0, s + 2 * ds), res.residual);
        x_free = x_good;
        return res;
      }
    }
  }
  x_free = x_good;
  res.converged = true;
  return res;
}

}  // namespace kelvin
