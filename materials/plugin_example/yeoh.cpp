/// \file
/// Example kelvin material plugin: a compressible Yeoh-type solid,
///   Ψ = c1 (I₁ − 3) + c2 (I₁ − 3)² − 2 c1 ln J + λ/2 (ln J)²,   I₁ = tr FᵀF,
///   P = 2 (c1 + 2 c2 (I₁ − 3)) F + (λ ln J − 2 c1) F⁻ᵀ.
/// At small strain it is linear elasticity with shear modulus μ = 2 c1 and Lamé λ; c2 stiffens
/// large stretches. Check it with `kelvin check-material build/libyeoh_plugin.so`.
#include <Eigen/LU>
#include <cmath>

#include "materials/plugin_sdk.hpp"

namespace {

using namespace kelvin;

class Yeoh final : public Material {
 public:
  std::string name() const override { return "yeoh"; }
  const std::vector<ParamInfo>& params() const override {
    static const std::vector<ParamInfo> p = {
        {"c1", "Pa", "half the small-strain shear modulus (mu = 2 c1)", 1e4, 0, 1e300, true},
        {"c2", "Pa", "stiffening with I1", 1e3, 0, 1e300, false},
        {"lambda", "Pa", "first Lamé parameter", 1e4, 0, 1e300, true},
    };
    return p;
  }
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }

  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override {
    const double c1 = in.q[0], c2 = in.q[1], lambda = in.q[2];
    const Mat3& F = in.F;
    const double J = F.determinant();
    if (!(J > 0)) return false;
    const Mat3 G = F.inverse().transpose();
    const double I1m3 = F.squaredNorm() - 3, lnJ = std::log(J);
    const double a = c1 + 2 * c2 * I1m3, b = lambda * lnJ - 2 * c1;
    if (request & kEnergy)
      out.energy = c1 * I1m3 + c2 * I1m3 * I1m3 - 2 * c1 * lnJ + 0.5 * lambda * lnJ * lnJ;
    if (request & kStress) out.P = 2 * a * F + b * G;
    if (request & kTangent) {
      // d(2aF) = 2a I + 8 c2 F⊗F ;  d(b G) = λ G⊗G − b G_il G_kj
      const Eigen::Map<const Eigen::Matrix<double, 9, 1>> f(F.data()), g(G.data());
      out.dPdF = 8 * c2 * f * f.transpose() + lambda * g * g.transpose();
      out.dPdF.diagonal().array() += 2 * a;
      for (int l = 0; l < 3; ++l)
        for (int k = 0; k < 3; ++k)
          for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) out.dPdF(i + 3 * j, k + 3 * l) -= b * G(i, l) * G(k, j);
    }
    if (request & kRateTangent) out.dPdFdot.setZero();
    if (request & kParamDerivative) {
      out.dPdq.resize(9, 3);
      Eigen::Map<Mat3>(out.dPdq.col(0).data()) = 2 * F - 2 * G;
      Eigen::Map<Mat3>(out.dPdq.col(1).data()) = 4 * I1m3 * F;
      Eigen::Map<Mat3>(out.dPdq.col(2).data()) = lnJ * G;
    }
    return true;
  }
};

}  // namespace

KELVIN_EXPORT_MATERIALS(Yeoh)
