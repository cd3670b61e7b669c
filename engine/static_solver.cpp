#include "engine/static_solver.hpp"

#include <fmt/format.h>

#include <Eigen/KLUSupport>
#include <cmath>

namespace kelvin {
namespace {

struct Residual {
  const FemModel& model;
  double t;
  Eigen::Matrix3Xd x, v;
  AssemblyOutput out;

  /// r(x) − s f_ext; false when an element is inadmissible at x.
  bool eval(const Eigen::VectorXd& xf, double s, bool tangent, Eigen::VectorXd& g) {
    model.expand(t, xf.data(), nullptr, x, v);
    AssemblyRequest req;
    req.stiffness = tangent;
    if (!model.assemble(x, v, req, out)) return false;
    g = out.force - s * model.gravity_force();
    return true;
  }
};

}  // namespace

Eigen::VectorXd rigid_initial_guess(const FemModel& model, double t) {
  Eigen::VectorXd x(model.num_dofs());
  const RigidPose pose = model.clamps().empty() ? RigidPose{} : model.clamps()[0].motion->at(t);
  Eigen::Matrix3Xd moved(3, model.mesh().num_nodes());
  for (int a = 0; a < moved.cols(); ++a) moved.col(a) = pose.position(model.mesh().nodes.col(a));
  model.restrict(moved, x.data());
  return x;
}

StaticResult solve_static(const FemModel& model, double t, Eigen::VectorXd& x_free,
                          const StaticOptions& opt) {
  StaticResult res;
  Residual R{model, t, {}, {}, {}};
  Eigen::VectorXd g, g_trial, x_trial;
  if (!R.eval(x_free, 1.0, false, g)) {
    res.message = fmt::format("element {} is inverted in the starting configuration",
                              R.out.failed_element);
    return res;
  }
  // Forces are compared to the load, or to the initial imbalance when there is no load.
  const double scale = std::max({model.gravity_force().norm(), g.norm(), 1e-300});
  Eigen::KLU<Eigen::SparseMatrix<double>> klu;
  bool analysed = false;

  // Load stepping: try the full load; on failure halve the increment.
  double s = 0, ds = 1;
  Eigen::VectorXd x_good = x_free;
  while (s < 1) {
    const double target = std::min(1.0, s + ds);
    Eigen::VectorXd x = x_good;
    bool ok = false;
    for (int it = 0; it < opt.max_iterations; ++it) {
      if (!R.eval(x, target, true, g)) break;
      res.residual = g.norm() / scale;
      if (res.residual <= opt.tolerance) {
        ok = true;
        break;
      }
      ++res.iterations;
      const Eigen::SparseMatrix<double> K = to_sparse_matrix(model.pattern(), R.out.K);
      if (!analysed) {
        klu.analyzePattern(K);
        analysed = true;
      }
      klu.factorize(K);
      if (klu.info() != Eigen::Success) break;
      const Eigen::VectorXd dx = klu.solve(-g);
      // Backtracking on the residual norm; inadmissible trial states count as worse.
      double alpha = 1;
      const double g0 = g.norm();
      bool accepted = false;
      for (int ls = 0; ls < 30 && !accepted; ++ls, alpha *= 0.5) {
        x_trial = x + alpha * dx;
        accepted = R.eval(x_trial, target, false, g_trial) &&
                   g_trial.norm() <= (1 - 1e-4 * alpha) * g0;
      }
      if (!accepted) {
        // Newton may stall at round-off level: accept when the step is negligible.
        if (dx.norm() <= 1e-13 * std::max(1.0, x.norm())) ok = true;
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
