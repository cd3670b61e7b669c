#include "materials/spline_material.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <string>

#include "materials/svd_utils.hpp"

namespace kelvin {
namespace {

/// Basis of the C¹ Hermite spline through values y at knots x with slopes m = D y:
/// for an argument s, the weights w(s) with spline(s) = w·y, its derivative
/// weights and the weights of ∫₁ˢ spline.
class HermiteBasis {
 public:
  explicit HermiteBasis(std::vector<double> x) : x_(std::move(x)) {
    const int K = static_cast<int>(x_.size());
    D_.setZero(K, K);
    // Knot slopes: derivative of the quartic through the five nearest knots
    // (fourth-order, so the Hermite cubic keeps its own O(h⁴) accuracy; three-point
    // slopes cost an order and missed neo-Hookean by ~3e-3 on this grid).
    constexpr int kStencil = 5;
    for (int k = 0; k < K; ++k) {
      const int first = std::clamp(k - kStencil / 2, 0, K - kStencil);
      Eigen::Matrix<double, kStencil, kStencil> V;  // V(p, m) = (x_m − x_k)^p
      for (int m = 0; m < kStencil; ++m) {
        const double t = x_[first + m] - x_[k];
        double tp = 1;
        for (int pw = 0; pw < kStencil; ++pw, tp *= t) V(pw, m) = tp;
      }
      Eigen::Matrix<double, kStencil, 1> rhs = Eigen::Matrix<double, kStencil, 1>::Zero();
      rhs[1] = 1;  // weights that differentiate every polynomial of degree < 5 exactly
      D_.row(k).segment<kStencil>(first) = V.fullPivLu().solve(rhs).transpose();
    }
    cum_.setZero(K, K);
    for (int k = 0; k + 1 < K; ++k) {
      const double h = x_[k + 1] - x_[k];
      cum_.row(k + 1) = cum_.row(k) + h * h / 12 * (D_.row(k) - D_.row(k + 1));
      cum_(k + 1, k) += h / 2;
      cum_(k + 1, k + 1) += h / 2;
    }
    int ref = -1;
    for (int k = 0; k < K; ++k)
      if (x_[k] == 1.0) ref = k;
    ref_ = cum_.row(ref);
  }
  int size() const { return static_cast<int>(x_.size()); }

  /// w: values, dw: derivatives, W: integrals from 1.
  void eval(double s, Eigen::RowVectorXd& w, Eigen::RowVectorXd& dw, Eigen::RowVectorXd& W) const {
    const int K = size();
    w.setZero(K);
    dw.setZero(K);
    if (s <= x_.front() || s >= x_.back()) {
      const int e = s <= x_.front() ? 0 : K - 1;
      const double d = s - x_[e];
      w = d * D_.row(e);
      w[e] += 1;
      dw = D_.row(e);
      W = cum_.row(e) + 0.5 * d * d * D_.row(e) - ref_;
      W[e] += d;
      return;
    }
    const int k = static_cast<int>(std::upper_bound(x_.begin(), x_.end(), s) - x_.begin()) - 1;
    const double h = x_[k + 1] - x_[k], t = (s - x_[k]) / h;
    const double t2 = t * t, t3 = t2 * t, t4 = t3 * t;
    const double h00 = 2 * t3 - 3 * t2 + 1, h10 = t3 - 2 * t2 + t, h01 = -2 * t3 + 3 * t2,
                 h11 = t3 - t2;
    const double g00 = 6 * t2 - 6 * t, g10 = 3 * t2 - 4 * t + 1, g01 = -g00, g11 = 3 * t2 - 2 * t;
    const double i00 = t - t3 + t4 / 2, i10 = t2 / 2 - 2 * t3 / 3 + t4 / 4, i01 = t3 - t4 / 2,
                 i11 = -t3 / 3 + t4 / 4;
    w = h * (h10 * D_.row(k) + h11 * D_.row(k + 1));
    w[k] += h00;
    w[k + 1] += h01;
    dw = g10 * D_.row(k) + g11 * D_.row(k + 1);
    dw[k] += g00 / h;
    dw[k + 1] += g01 / h;
    W = cum_.row(k) - ref_ + h * h * (i10 * D_.row(k) + i11 * D_.row(k + 1));
    W[k] += h * i00;
    W[k + 1] += h * i01;
  }

 private:
  std::vector<double> x_;
  Eigen::MatrixXd D_, cum_;
  Eigen::RowVectorXd ref_;
};

const HermiteBasis& stretch_basis() {
  static const HermiteBasis b(SplineMaterial::stretch_knots());
  return b;
}
const HermiteBasis& volume_basis() {
  static const HermiteBasis b(SplineMaterial::volume_knots());
  return b;
}

}  // namespace

const std::vector<double>& SplineMaterial::stretch_knots() {
  // Roughly geometric (ratio ≈ 1.15): the 1/σ-type terms of common energies need
  // h/σ ≲ 0.2 for the cubic to stay within 1e-3 of them. 1 must be a knot.
  static const std::vector<double> x = {0.3, 0.35, 0.4,  0.46, 0.53, 0.61, 0.7,  0.8, 0.9, 1.0,
                                        1.1, 1.2,  1.35, 1.5,  1.7,  1.95, 2.25, 2.6, 3.0};
  return x;
}

const std::vector<double>& SplineMaterial::volume_knots() {
  static const std::vector<double> x = {0.2,  0.23, 0.265, 0.3,  0.35, 0.4, 0.46, 0.53,
                                        0.61, 0.7,  0.8,   0.9,  1.0,  1.1, 1.2,  1.35,
                                        1.5,  1.7,  1.95,  2.25, 2.6,  3.0};
  return x;
}

std::vector<double> SplineMaterial::neo_hookean_values(double lambda, double mu) {
  std::vector<double> q;
  for (double s : stretch_knots()) q.push_back(mu * (s - 1 / s));
  for (double J : volume_knots()) q.push_back(0.5 * lambda * (J - 1 / J));
  return q;
}

const std::vector<ParamInfo>& SplineMaterial::params() const {
  static const std::vector<ParamInfo> p = [] {
    std::vector<ParamInfo> v;
    const std::vector<double> d = neo_hookean_values(1e4, 1e4);
    // Appending (rather than "f" + to_string) sidesteps a GCC 12 -Wrestrict false positive.
    auto add = [&](char prefix, size_t k, const char* what, double knot, double value) {
      ParamInfo info;
      info.name.push_back(prefix);
      info.name.append(std::to_string(k + 1));
      info.unit = "Pa";
      info.description.append(what).append(std::to_string(knot));
      info.default_value = value;
      v.push_back(std::move(info));
    };
    const auto& xs = stretch_knots();
    const auto& xj = volume_knots();
    for (size_t k = 0; k < xs.size(); ++k)
      add('f', k, "f'(s) at principal stretch s = ", xs[k], d[k]);
    for (size_t k = 0; k < xj.size(); ++k)
      add('h', k, "h'(J) at volume ratio J = ", xj[k], d[xs.size() + k]);
    return v;
  }();
  return p;
}

bool SplineMaterial::evaluate(const MaterialPoint& in, unsigned request,
                              MaterialResponse& out) const {
  if (!(in.F.determinant() > 0)) return false;
  const HermiteBasis& fb = stretch_basis();
  const HermiteBasis& hb = volume_basis();
  const int K = fb.size(), M = hb.size();
  const Eigen::Map<const Eigen::VectorXd> yf(in.q, K), yh(in.q + K, M);

  const SignedSvd svd = signed_svd(in.F);
  const Eigen::Vector3d& s = svd.sigma;
  const double J = s.prod();
  Eigen::RowVectorXd wf[3], dwf[3], Wf[3], wh, dwh, Wh;
  for (int i = 0; i < 3; ++i) fb.eval(s[i], wf[i], dwf[i], Wf[i]);
  hb.eval(J, wh, dwh, Wh);
  const double hp = wh.dot(yh), hpp = dwh.dot(yh);
  Eigen::Vector3d fp, p;
  for (int i = 0; i < 3; ++i) {
    fp[i] = wf[i].dot(yf);
    p[i] = fp[i] + hp * J / s[i];
  }

  if (request & kEnergy) out.energy = (Wf[0] + Wf[1] + Wf[2]).dot(yf) + Wh.dot(yh);
  if (request & kStress) out.P = principal_stress(svd, p);
  if (request & kTangent) {
    Mat3 H;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        H(i, j) =
            hpp * (J / s[i]) * (J / s[j]) + (i == j ? dwf[i].dot(yf) : hp * J / (s[i] * s[j]));
    Eigen::Vector3d divided;
    for (int k = 0; k < 3; ++k) {
      const int i = kSvdPairs[k][0], j = kSvdPairs[k][1], l = 3 - i - j;
      const double gap = s[i] - s[j];
      double df;
      if (std::abs(gap) > 1e-6 * std::max(1.0, std::abs(s[i]))) {
        df = (fp[i] - fp[j]) / gap;
      } else {
        // L'Hôpital: the divided difference of f' tends to f'' as the stretches meet.
        Eigen::RowVectorXd w, dw, W;
        fb.eval(0.5 * (s[i] + s[j]), w, dw, W);
        df = dw.dot(yf);
      }
      divided[k] = df - hp * s[l];
    }
    out.dPdF = principal_tangent(svd, p, H, divided);
  }
  if (request & kRateTangent) out.dPdFdot.setZero();
  if (request & kParamDerivative) {
    // P is linear in q: column k is the stress of basis function k alone.
    out.dPdq.resize(9, K + M);
    for (int k = 0; k < K; ++k)
      Eigen::Map<Mat3>(out.dPdq.col(k).data()) =
          principal_stress(svd, Eigen::Vector3d(wf[0][k], wf[1][k], wf[2][k]));
    for (int m = 0; m < M; ++m)
      Eigen::Map<Mat3>(out.dPdq.col(K + m).data()) =
          principal_stress(svd, wh[m] * J * s.cwiseInverse());
  }
  return true;
}

}  // namespace kelvin
