#include "materials/fiber.hpp"

#include <cmath>
#include <limits>

#include "materials/neo_hookean.hpp"

namespace kelvin {

const std::vector<ParamInfo>& FiberReinforced::params() const {
  static const std::vector<ParamInfo> p = {
      {"lambda", "Pa", "first Lamé parameter of the matrix", 1e4, 0, 1e300, true},
      {"mu", "Pa", "shear modulus of the matrix", 1e4, 0, 1e300, true},
      {"k1", "Pa", "fibre stiffness", 1e4, 0, 1e300, false},
      {"k2", "1", "fibre exponential stiffening", 1.0, 0, 1e300, false},
  };
  return p;
}

bool FiberReinforced::evaluate(const MaterialPoint& in, unsigned request,
                               MaterialResponse& out) const {
  static const NeoHookean matrix;
  if (!matrix.evaluate(in, request, out)) return false;  // fills the λ, μ columns of dPdq
  if (request & kParamDerivative) out.dPdq.conservativeResize(9, 4);

  Eigen::Vector3d a(1, 0, 0);
  if (in.state) a = Eigen::Vector3d(in.state[0], in.state[1], in.state[2]);
  if (!(a.norm() > 0)) return false;
  a.normalize();
  const double k1 = in.q[2], k2 = in.q[3];
  const Eigen::Vector3d b = in.F * a;
  const double x = b.squaredNorm() - 1;  // I₄ − 1

  if (request & kParamDerivative) out.dPdq.rightCols(2).setZero();
  // At the kink I₄ = 1 (to rounding; e.g. a pure shear across the fibre) ψ'' jumps
  // from 0 to k1: return the mean of the one-sided tangents, which is what a central
  // difference sees, instead of whichever side rounding happened to pick.
  if (std::abs(x) <= 64 * std::numeric_limits<double>::epsilon()) {
    if (request & kTangent) {
      const Mat3 Faa = b * a.transpose();
      const Eigen::Map<const Eigen::Matrix<double, 9, 1>> g(Faa.data());
      out.dPdF.noalias() += 2 * k1 * g * g.transpose();
    }
    return true;
  }
  if (x < 0) return true;  // fibres slack: nothing to add
  const double ex = std::exp(k2 * x * x);
  const double dpsi = k1 * x * ex;                      // ∂Ψ_f/∂I₄
  const double d2psi = k1 * ex * (1 + 2 * k2 * x * x);  // ∂²Ψ_f/∂I₄²
  const Mat3 Faa = b * a.transpose();                   // ∂I₄/∂F = 2 F a aᵀ
  if (request & kEnergy)
    // expm1/k2 keeps the k2 → 0 limit k1 x²/2 exact.
    out.energy += k2 > 0 ? k1 / (2 * k2) * std::expm1(k2 * x * x) : 0.5 * k1 * x * x;
  if (request & kStress) out.P += 2 * dpsi * Faa;
  if (request & kTangent) {
    // dP_ij/dF_kl = 2ψ' δ_ik a_j a_l + 4ψ'' (Fa)_i a_j (Fa)_k a_l
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> g(Faa.data());
    out.dPdF.noalias() += 4 * d2psi * g * g.transpose();
    for (int l = 0; l < 3; ++l)
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) out.dPdF(i + 3 * j, i + 3 * l) += 2 * dpsi * a[j] * a[l];
  }
  if (request & kParamDerivative) {
    Eigen::Map<Mat3>(out.dPdq.col(2).data()) = 2 * x * ex * Faa;
    Eigen::Map<Mat3>(out.dPdq.col(3).data()) = 2 * dpsi * x * x * Faa;
  }
  return true;
}

}  // namespace kelvin
