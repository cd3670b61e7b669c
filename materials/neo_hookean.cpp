#include "materials/neo_hookean.hpp"

#include <Eigen/LU>
#include <cmath>

namespace kelvin {

const std::vector<ParamInfo>& NeoHookean::params() const {
  static const std::vector<ParamInfo> p = {
      {"lambda", "Pa", "first Lamé parameter", 1e4, 0, 1e300, true},
      {"mu", "Pa", "shear modulus (second Lamé parameter)", 1e4, 0, 1e300, true},
  };
  return p;
}

bool NeoHookean::evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const {
  const Mat3& F = in.F;
  const double lambda = in.q[0], mu = in.q[1];
  const double J = F.determinant();
  if (!(J > 0)) return false;
  const Mat3 G = F.inverse().transpose();  // F⁻ᵀ = ∂J/∂F / J
  const double J2 = J * J;

  if (request & kEnergy) {
    const double lnJ = std::log(J);
    out.energy = 0.5 * lambda * (0.5 * (J2 - 1) - lnJ) + 0.5 * mu * (F.squaredNorm() - 3 - 2 * lnJ);
  }
  if (request & kStress) out.P = 0.5 * lambda * (J2 - 1) * G + mu * (F - G);
  if (request & kTangent) {
    // ∂G_ij/∂F_kl = −G_il G_kj and ∂J²/∂F = 2J² G give
    // dP_ij/dF_kl = μ δ_ik δ_jl + λ J² G_ij G_kl − (λ/2 (J²−1) − μ) G_il G_kj.
    const double c = 0.5 * lambda * (J2 - 1) - mu;
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> g(G.data());
    out.dPdF.noalias() = lambda * J2 * g * g.transpose();
    out.dPdF.diagonal().array() += mu;
    for (int l = 0; l < 3; ++l)
      for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < 3; ++i) out.dPdF(i + 3 * j, k + 3 * l) -= c * G(i, l) * G(k, j);
  }
  if (request & kRateTangent) out.dPdFdot.setZero();
  if (request & kParamDerivative) {
    out.dPdq.resize(9, 2);
    Eigen::Map<Mat3>(out.dPdq.col(0).data()) = 0.5 * (J2 - 1) * G;
    Eigen::Map<Mat3>(out.dPdq.col(1).data()) = F - G;
  }
  return true;
}

}  // namespace kelvin
