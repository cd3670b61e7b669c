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
/// function of `n` scalar inputs with analytic.rows() values) against `analytic`.
double sweep(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
             const Eigen::VectorXd& x0, const Eigen::MatrixXd& analytic, double floor) {
  double best = INFINITY;
  const int n = static_cast<int>(x0.size());
  for (double h : kSteps) {
    Eigen::MatrixXd fd(analytic.rows(), n);
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

Eigen::VectorXd vec(const Mat3& A) {
  return Eigen::Map<const Eigen::Matrix<double, 9, 1>>(A.data());
}
Mat3 mat(const Eigen::VectorXd& v) {
  return Eigen::Map<const Mat3>(v.data());
}

/// The superposed rotation of the objectivity checks.
const Mat3 kObjectivityRotation =
    Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();

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
  const int nz = material.internal_size();
  // Internal variables are checked away from their relaxed value (where a branch
  // carries no stress and stays put), at a perturbation drawn once per state.
  std::mt19937_64 rng(options.seed + 1);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  auto point = [&](const Mat3& F, const Mat3& Fdot, const double* qv, const double* z) {
    MaterialPoint p;
    p.F = F;
    p.Fdot = Fdot;
    p.q = qv;
    p.internal = nz ? z : nullptr;
    return p;
  };
  auto stress = [&](const Mat3& F, const Mat3& Fdot, const double* qv, const double* z) {
    MaterialResponse r;
    material.evaluate(point(F, Fdot, qv, z), kStress, r);
    return vec(r.P);
  };
  auto rate = [&](const Mat3& F, const double* qv, const double* z) {
    InternalResponse r;
    material.evolve(point(F, Mat3::Zero(), qv, z), 0, r);
    return Eigen::VectorXd(r.rate);
  };

  for (const auto& s : material_test_states(options)) {
    Eigen::VectorXd z = Eigen::VectorXd::Zero(nz);
    if (nz) {
      material.relaxed_internal(s.F, q.data(), z.data());
      for (int k = 0; k < nz; ++k) z[k] += u(rng) * std::max(1.0, std::abs(z[k]));
    }
    MaterialResponse r;
    const unsigned all = kStress | kTangent | kRateTangent | kParamDerivative |
                         (material.has_energy() ? kEnergy : 0u);
    if (!material.evaluate(point(s.F, s.Fdot, q.data(), z.data()), all, r)) {
      out.push_back({"evaluate", s.label, INFINITY, tol});
      continue;
    }
    const double floor = 1e-12 * std::max(1.0, r.P.norm());
    Eigen::VectorXd f0 = vec(s.F), fd0 = vec(s.Fdot);

    out.push_back(
        {"dP/dF", s.label,
         sweep([&](const Eigen::VectorXd& f) { return stress(mat(f), s.Fdot, q.data(), z.data()); },
               f0, r.dPdF, floor),
         tol});
    out.push_back(
        {"dP/dFdot", s.label,
         sweep([&](const Eigen::VectorXd& f) { return stress(s.F, mat(f), q.data(), z.data()); },
               fd0, r.dPdFdot, floor),
         tol});
    if (nq > 0)
      out.push_back(
          {"dP/dq", s.label,
           sweep(
               [&](const Eigen::VectorXd& qv) { return stress(s.F, s.Fdot, qv.data(), z.data()); },
               Eigen::Map<const Eigen::VectorXd>(q.data(), nq), r.dPdq, floor),
           tol});
    if (material.has_energy()) {
      // P = ∂Ψ/∂F (at fixed internal variables): differentiate the scalar energy,
      // packed as a one-row 9-column Jacobian.
      auto energy = [&](const Eigen::VectorXd& f) {
        MaterialResponse e;
        material.evaluate(point(mat(f), s.Fdot, q.data(), z.data()), kEnergy, e);
        return Eigen::VectorXd::Constant(1, e.energy);
      };
      out.push_back({"P = dPsi/dF", s.label, sweep(energy, f0, vec(r.P).transpose(), floor), tol});
      out.push_back({"dP/dF symmetric", s.label,
                     rel_error(r.dPdF, r.dPdF.transpose(), 1e-12 * std::max(1.0, r.dPdF.norm())),
                     tol});
    }
    if (nz) {
      out.push_back(
          {"dP/dz", s.label,
           sweep(
               [&](const Eigen::VectorXd& zv) { return stress(s.F, s.Fdot, q.data(), zv.data()); },
               z, r.dPdz, floor),
           tol});
      InternalResponse e;
      material.evolve(point(s.F, s.Fdot, q.data(), z.data()), kTangent | kParamDerivative, e);
      const double rate_floor = 1e-12 * std::max(1.0, e.rate.norm());
      out.push_back(
          {"df/dF", s.label,
           sweep([&](const Eigen::VectorXd& f) { return rate(mat(f), q.data(), z.data()); }, f0,
                 e.dF, rate_floor),
           tol});
      out.push_back(
          {"df/dz", s.label,
           sweep([&](const Eigen::VectorXd& zv) { return rate(s.F, q.data(), zv.data()); }, z, e.dz,
                 rate_floor),
           tol});
      if (nq > 0)
        out.push_back(
            {"df/dq", s.label,
             sweep([&](const Eigen::VectorXd& qv) { return rate(s.F, qv.data(), z.data()); },
                   Eigen::Map<const Eigen::VectorXd>(q.data(), nq), e.dq, rate_floor),
             tol});
      // The relaxed value is where the variables stay put while F is held.
      Eigen::VectorXd relaxed(nz);
      material.relaxed_internal(s.F, q.data(), relaxed.data());
      out.push_back({"f = 0 when relaxed", s.label,
                     rate(s.F, q.data(), relaxed.data()).norm() / std::max(e.rate.norm(), 1e-300),
                     tol});
      // Internal variables are reference-frame quantities: a superposed rotation
      // leaves their law unchanged.
      out.push_back(
          {"f objective", s.label,
           rel_error(rate(kObjectivityRotation * s.F, q.data(), z.data()), e.rate, rate_floor),
           tol});
    }
    // Objectivity: a superposed rotation Q (constant in time) gives P(QF, QḞ) = Q P(F, Ḟ).
    const Mat3& Q = kObjectivityRotation;
    const Eigen::VectorXd Pq = stress(Q * s.F, Q * s.Fdot, q.data(), z.data());
    out.push_back({"objectivity", s.label, rel_error(mat(Pq), Q * r.P, floor), tol});
  }
  // Zero stress in the rest state (F = I, Ḟ = 0, internal variables relaxed) for every
  // model kelvin ships.
  Eigen::VectorXd z_rest = Eigen::VectorXd::Zero(nz);
  if (nz) material.relaxed_internal(Mat3::Identity(), q.data(), z_rest.data());
  MaterialResponse rest;
  if (material.evaluate(point(Mat3::Identity(), Mat3::Zero(), q.data(), z_rest.data()), kStress,
                        rest)) {
    double scale = 1;
    for (double v : q) scale = std::max(scale, std::abs(v));
    out.push_back({"zero stress at rest", "F=I", rest.P.norm() / scale, tol});
  }
  return out;
}

}  // namespace kelvin
