#include "materials/maxwell.hpp"

namespace kelvin {
namespace {

/// Tensor indices of the six internal variables.
constexpr int kRow[6] = {0, 1, 2, 0, 0, 1};
constexpr int kCol[6] = {0, 1, 2, 1, 2, 2};

Mat3 green_strain(const Mat3& F) {
  return 0.5 * (F.transpose() * F - Mat3::Identity());
}

/// The symmetric tensor of six components z.
Mat3 tensor_of(const double* z) {
  Mat3 Z;
  for (int k = 0; k < 6; ++k) Z(kRow[k], kCol[k]) = Z(kCol[k], kRow[k]) = z[k];
  return Z;
}

}  // namespace

const std::vector<ParamInfo>& MaxwellBranch::params() const {
  static const std::vector<ParamInfo> p = {
      {"g", "Pa", "branch shear modulus (0: no branch)", 0, 0, 1e300, false},
      {"tau", "s", "relaxation time", 0.1, 0, 1e300, true},
  };
  return p;
}

void MaxwellBranch::relaxed_internal(const Mat3& F, const double*, double* z) const {
  const Mat3 E = green_strain(F);
  for (int k = 0; k < 6; ++k) z[k] = E(kRow[k], kCol[k]);
}

void MaxwellBranch::evolve(const MaterialPoint& in, unsigned request, InternalResponse& out) const {
  const double tau = in.q[1];
  const Mat3 E = green_strain(in.F);
  out.rate.resize(6);
  for (int k = 0; k < 6; ++k) out.rate[k] = (E(kRow[k], kCol[k]) - in.internal[k]) / tau;
  if (request & kTangent) {
    // ∂E_ij/∂F_ab = ½ (δ_bi F_aj + F_ai δ_bj), F flattened as a + 3b.
    out.dF.setZero(6, 9);
    for (int k = 0; k < 6; ++k) {
      const int i = kRow[k], j = kCol[k];
      for (int a = 0; a < 3; ++a) {
        out.dF(k, a + 3 * i) += 0.5 * in.F(a, j) / tau;
        out.dF(k, a + 3 * j) += 0.5 * in.F(a, i) / tau;
      }
    }
    out.dz = -Eigen::MatrixXd::Identity(6, 6) / tau;
  }
  if (request & kParamDerivative) {
    out.dq.setZero(6, 2);
    out.dq.col(1) = -out.rate / tau;
  }
}

bool MaxwellBranch::evaluate(const MaterialPoint& in, unsigned request,
                             MaterialResponse& out) const {
  const double mu = in.q[0];
  const Mat3& F = in.F;
  // Without internal variables (a material check) the branch is relaxed at rest: Z = 0.
  const Mat3 D = in.internal ? Mat3(green_strain(F) - tensor_of(in.internal)) : green_strain(F);
  const Mat3 S = 2 * mu * D;
  out.P = F * S;
  if (request & kEnergy) out.energy = mu * D.squaredNorm();
  if ((request & kTangent) && mu == 0) {
    // A branch screened at g = 0 carries no stress: skip the tangent's loop.
    out.dPdF.setZero();
    out.dPdz.setZero(9, 6);
  } else if (request & kTangent) {
    // dP = dF S + F (2μ sym(Fᵀ dF)) at fixed Z.
    for (int b = 0; b < 3; ++b)
      for (int a = 0; a < 3; ++a) {
        Mat3 dF = Mat3::Zero();
        dF(a, b) = 1;
        const Mat3 dE = 0.5 * (F.transpose() * dF + dF.transpose() * F);
        const Mat3 dP = dF * S + F * (2 * mu * dE);
        out.dPdF.col(a + 3 * b) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dP.data());
      }
    out.dPdz.resize(9, 6);
    for (int k = 0; k < 6; ++k) {
      double unit[6] = {0, 0, 0, 0, 0, 0};
      unit[k] = 1;
      const Mat3 dP = -2 * mu * F * tensor_of(unit);
      out.dPdz.col(k) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dP.data());
    }
  }
  if (request & kParamDerivative) {
    out.dPdq.setZero(9, 2);
    const Mat3 dP = F * (2 * D);
    out.dPdq.col(0) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dP.data());
  }
  return out.P.allFinite();
}

}  // namespace kelvin
