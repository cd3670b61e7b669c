#include "materials/power_law.hpp"

#include <Eigen/LU>
#include <cfloat>
#include <cmath>
#include <unsupported/Eigen/AutoDiff>

namespace kelvin {
namespace {

/// σ-to-P pull-back of ν γ̇^(h−1) d; `power_law` false means h ≡ 1 (no pow at all,
/// so Newtonian stays exact and cheap).
template <class S>
Eigen::Matrix<S, 3, 3> viscous_stress(const Eigen::Matrix<S, 3, 3>& F,
                                      const Eigen::Matrix<S, 3, 3>& Fdot, const S& nu, const S& h,
                                      bool power_law) {
  using std::exp;
  using std::log;
  using std::sqrt;
  const S J = F.determinant();
  const Eigen::Matrix<S, 3, 3> Finv = F.inverse();
  const Eigen::Matrix<S, 3, 3> L = Fdot * Finv;
  const Eigen::Matrix<S, 3, 3> d = L + L.transpose();
  S coeff = nu;
  if (power_law) {
    // γ̇^(h−1) as exp((h−1) ln γ̇): AutoDiffScalar has no pow(AD, AD).
    const S gamma = sqrt(S(0.5) * d.squaredNorm());
    const S exponent = h - S(1);
    coeff = nu * exp(exponent * log(gamma));
  }
  return (J * coeff) * d * Finv.transpose();
}

/// Evaluates P and, when asked, all its derivatives in one AD sweep over
/// (F, Ḟ, q) — 18 + nq directions.
bool evaluate_viscous(const MaterialPoint& in, unsigned request, MaterialResponse& out,
                      bool power_law) {
  const int nq = power_law ? 2 : 1;
  const double J = in.F.determinant();
  if (!(J > 0)) return false;
  const double nu = in.q[0], h = power_law ? in.q[1] : 1.0;
  const Mat3 L = in.Fdot * in.F.inverse();
  const bool at_rest = !(L.norm() > DBL_MIN);

  const unsigned derivs = kTangent | kRateTangent | kParamDerivative;
  if (at_rest) {
    if (request & kStress) out.P.setZero();
    if (request & kTangent) out.dPdF.setZero();
    if (request & kRateTangent) out.dPdFdot.setZero();
    if (request & kParamDerivative) out.dPdq.setZero(9, nq);
    if (request & kEnergy) out.energy = 0;
    return true;
  }
  if (request & kEnergy) out.energy = 0;
  if (!(request & derivs)) {
    if (request & kStress) out.P = viscous_stress<double>(in.F, in.Fdot, nu, h, power_law);
    return true;
  }

  using Deriv = Eigen::Matrix<double, 20, 1>;
  using AD = Eigen::AutoDiffScalar<Deriv>;
  Eigen::Matrix<AD, 3, 3> F, Fd;
  for (int k = 0; k < 9; ++k) {
    F(k % 3, k / 3) = AD(in.F(k % 3, k / 3), 20, k);
    Fd(k % 3, k / 3) = AD(in.Fdot(k % 3, k / 3), 20, 9 + k);
  }
  const AD nu_ad(nu, 20, 18), h_ad(h, 20, 19);
  const Eigen::Matrix<AD, 3, 3> P = viscous_stress<AD>(F, Fd, nu_ad, h_ad, power_law);
  if (request & kStress)
    for (int k = 0; k < 9; ++k) out.P(k % 3, k / 3) = P(k % 3, k / 3).value();
  if (request & kParamDerivative) out.dPdq.resize(9, nq);
  for (int a = 0; a < 9; ++a) {
    const Deriv& g = P(a % 3, a / 3).derivatives();
    if (request & kTangent) out.dPdF.row(a) = g.segment<9>(0).transpose();
    if (request & kRateTangent) out.dPdFdot.row(a) = g.segment<9>(9).transpose();
    if (request & kParamDerivative) out.dPdq.row(a) = g.segment(18, nq).transpose();
  }
  return true;
}

}  // namespace

const std::vector<ParamInfo>& PowerLawViscosity::params() const {
  static const std::vector<ParamInfo> p = {
      {"nu", "Pa s^h", "viscosity coefficient", 1.0, 0, 1e300, true},
      {"h", "1", "flow index (1 = Newtonian, < 1 shear-thinning)", 1.0, 0, 1e300, true},
  };
  return p;
}

bool PowerLawViscosity::evaluate(const MaterialPoint& in, unsigned request,
                                 MaterialResponse& out) const {
  return evaluate_viscous(in, request, out, true);
}

const std::vector<ParamInfo>& NewtonianViscosity::params() const {
  static const std::vector<ParamInfo> p = {
      {"nu", "Pa s", "dynamic viscosity", 1.0, 0, 1e300, true},
  };
  return p;
}

bool NewtonianViscosity::evaluate(const MaterialPoint& in, unsigned request,
                                  MaterialResponse& out) const {
  return evaluate_viscous(in, request, out, false);
}

}  // namespace kelvin
