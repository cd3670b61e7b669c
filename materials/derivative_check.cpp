#include "materials/derivative_check.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <functional>

namespace kelvin {
namespace {

constexpr double kSteps[] = {1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7};

/// Relative error ‖a − b‖ / max(‖b‖, floor): the floor keeps exactly-zero
/// derivatives (e.g. an elastic model's dP/dḞ) from dividing by zero.
double rel_error(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, double floor) {
  return (a - b).norm() / std::max(b.norm(), floor);
}

/// Best relative error over the step sweep of a central difference of f (a
/// 9-vector function of `n` scalar inputs) against `analytic` (9 × n).
double sweep(const std::function<Eigen::Matrix<double, 9, 1>(const Eigen::VectorXd&)>& f,
             const Eigen::VectorXd& x0, const Eigen::MatrixXd& analytic, double floor) {
  double best = INFINITY;
  const int n = static_cast<int>(x0.size());
  for (double h : kSteps) {
    Eigen::MatrixXd fd(9, n);
    for (int k = 0; k < n; ++k) {
      const double step = h * std::max(1.0, std::abs(x0[k]));
      Eigen::VectorXd xp = x0, xm = x0;
      xp[k] += step;
      xm[k] -= step;
      fd.col(k) = (f(xp) - f(xm)) / (2 * step);
    }
    if (fd.allFinite()) best = std::min(best, rel_error(fd, analytic, floor));
  }
  return best;
}

Eigen::Matrix<double, 9, 1> vec(const Mat3& A) {
  return Eigen::Map<const Eigen::Matrix<double, 9, 1>>(A.data());
}
Mat3 mat(const Eigen::VectorXd& v) {
  return Eigen::Map<const Mat3>(v.data());
}

}  // namespace

std::vector<MaterialState> material_test_states(const MaterialCheckOptions& options) {
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> u(-1, 1);
  auto random3 = [&](double s) {
    Mat3 A;
    for (int k = 0; k < 9; ++k) A(k % 3, k / 3) = s * u(rng);
    return A;
  };
  auto rotation = [&] {
    Eigen::Vector3d axis(u(rng), u(rng), u(rng));
    return Eigen::AngleAxisd(3 * u(rng), axis.normalized()).toRotationMatrix();
  };
  std::vector<MaterialState> states;
  for (int i = 0; i < options.random_states; ++i)
    states.push_back({"random", Mat3::Identity() + random3(0.3), random3(1.0)});
  const Mat3 R = rotation();
  states.push_back({"compression J=0.42",
                    R * Eigen::Vector3d(0.6, 0.8, 0.88).asDiagonal() * rotation(), random3(1.0)});
  states.push_back({"stretch 2x", R * Eigen::Vector3d(2.0, 0.75, 0.8).asDiagonal(), random3(1.0)});
  Mat3 shear = Mat3::Identity();
  shear(0, 1) = 0.8;
  states.push_back({"shear 0.8", rotation() * shear, random3(1.0)});
  states.push_back({"near inversion J=0.05",
                    rotation() * Eigen::Vector3d(0.25, 0.4, 0.5).asDiagonal(), random3(1.0)});
  return states;
}

std::vector<DerivativeCheck> check_material_derivatives(const Material& material,
                                                        const std::vector<double>& q,
                                                        const MaterialCheckOptions& options) {
  std::vector<DerivativeCheck> out;
  const double tol = options.tolerance;
  const int nq = static_cast<int>(q.size());
  auto eval = [&](const Mat3& F, const Mat3& Fdot, const double* qv, unsigned req,
                  MaterialResponse& r) {
    MaterialPoint p;
    p.F = F;
    p.Fdot = Fdot;
    p.q = qv;
    return material.evaluate(p, req, r);
  };
  auto stress = [&](const Mat3& F, const Mat3& Fdot, const double* qv) {
    MaterialResponse r;
    eval(F, Fdot, qv, kStress, r);
    return vec(r.P);
  };

  for (const auto& s : material_test_states(options)) {
    MaterialResponse r;
    const unsigned all = kStress | kTangent | kRateTangent | kParamDerivative |
                         (material.has_energy() ? kEnergy : 0u);
    if (!eval(s.F, s.Fdot, q.data(), all, r)) {
      out.push_back({"evaluate", s.label, INFINITY, tol});
      continue;
    }
    const double floor = 1e-12 * std::max(1.0, r.P.norm());
    Eigen::VectorXd f0 = vec(s.F), fd0 = vec(s.Fdot);

    out.push_back({"dP/dF", s.label,
                   sweep([&](const Eigen::VectorXd& f) { return stress(mat(f), s.Fdot, q.data()); },
                         f0, r.dPdF, floor),
                   tol});
    out.push_back({"dP/dFdot", s.label,
                   sweep([&](const Eigen::VectorXd& f) { return stress(s.F, mat(f), q.data()); },
                         fd0, r.dPdFdot, floor),
                   tol});
    if (nq > 0)
      out.push_back(
          {"dP/dq", s.label,
           sweep([&](const Eigen::VectorXd& qv) { return stress(s.F, s.Fdot, qv.data()); },
                 Eigen::Map<const Eigen::VectorXd>(q.data(), nq), r.dPdq, floor),
           tol});
    if (material.has_energy()) {
      // P = ∂Ψ/∂F: differentiate the scalar energy; pack it as a 9-vector column.
      auto energy = [&](const Eigen::VectorXd& f) {
        MaterialResponse e;
        eval(mat(f), s.Fdot, q.data(), kEnergy, e);
        Eigen::Matrix<double, 9, 1> v = Eigen::Matrix<double, 9, 1>::Zero();
        v[0] = e.energy;
        return v;
      };
      Eigen::MatrixXd analytic = Eigen::MatrixXd::Zero(9, 9);
      analytic.row(0) = vec(r.P).transpose();
      out.push_back({"P = dPsi/dF", s.label, sweep(energy, f0, analytic, floor), tol});
      out.push_back({"dP/dF symmetric", s.label,
                     rel_error(r.dPdF, r.dPdF.transpose(), 1e-12 * std::max(1.0, r.dPdF.norm())),
                     tol});
    }
    // Objectivity: a superposed rotation Q (constant in time) gives P(QF, QḞ) = Q P(F, Ḟ).
    const Mat3 Q = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    MaterialResponse rq;
    eval(Q * s.F, Q * s.Fdot, q.data(), kStress, rq);
    out.push_back({"objectivity", s.label, rel_error(rq.P, Q * r.P, floor), tol});
  }
  // Zero stress in the rest state (F = I, Ḟ = 0) for every model kelvin ships.
  MaterialResponse rest;
  if (eval(Mat3::Identity(), Mat3::Zero(), q.data(), kStress, rest)) {
    double scale = 1;
    for (double v : q) scale = std::max(scale, std::abs(v));
    out.push_back({"zero stress at rest", "F=I", rest.P.norm() / scale, tol});
  }
  return out;
}

}  // namespace kelvin
