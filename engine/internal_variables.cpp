// FemModel's internal variables (materials with internal_size() > 0): their
// numbering, relaxed state, error weights and linearisation, element by element.
#include <Eigen/LU>
#include <algorithm>

#include "engine/fem_model.hpp"
#include "engine/threads.hpp"

namespace kelvin {
namespace {

/// Below this many blocks a loop runs on one thread (as FemModel's element loops).
constexpr int kParallelMin = 256;

}  // namespace

void FemModel::number_internal_variables() {
  const int ne = mesh_.num_tets();
  internal_base_.assign(terms_.size(), -1);
  internal_first_block_.assign(terms_.size(), -1);
  for (size_t t = 0; t < terms_.size(); ++t) {
    const int m = terms_[t].model->internal_size();
    if (m <= 0) continue;
    internal_base_[t] = num_internal_;
    internal_first_block_[t] = static_cast<int>(internal_blocks_.size());
    for (int e = 0; e < ne; ++e)
      internal_blocks_.push_back({static_cast<int>(t), e, num_internal_ + m * e, m});
    num_internal_ += m * ne;
  }
}

MaterialPoint FemModel::internal_point(const InternalBlock& b, const Eigen::Matrix3Xd& x,
                                       const double* z) const {
  const auto& el = elements_[b.element];
  const MaterialTerm& term = terms_[b.term];
  Eigen::Matrix<double, 3, 4> xe;
  for (int a = 0; a < 4; ++a) xe.col(a) = x.col(el.nodes[a]);
  MaterialPoint mp;
  mp.F = xe * el.G.transpose();
  mp.q = term.q.col(b.element).data();
  mp.state = term.state.size() ? term.state.col(b.element).data() : nullptr;
  mp.internal = z ? z + b.offset : nullptr;
  mp.element = b.element;
  return mp;
}

void FemModel::relaxed_internal(const Eigen::Matrix3Xd& x, double* z) const {
  for (const InternalBlock& b : internal_blocks_) {
    const MaterialPoint mp = internal_point(b, x, nullptr);
    terms_[b.term].model->relaxed_internal(mp.F, mp.q, z + b.offset);
  }
}

InternalLinearisation FemModel::relaxed_linearisation(const Eigen::Matrix3Xd& x) const {
  std::vector<double> z(num_internal_);
  relaxed_internal(x, z.data());
  InternalLinearisation lin;
  linearise_internal(x, x, z.data(), kTangent, lin);
  return lin;
}

void FemModel::relaxed_internal_change(const Eigen::Matrix3Xd& x, const double* dx_free,
                                       double* dz) const {
  if (internal_blocks_.empty()) return;
  const InternalLinearisation lin = relaxed_linearisation(x);
  for (size_t k = 0; k < internal_blocks_.size(); ++k) {
    const InternalBlock& b = internal_blocks_[k];
    Eigen::Map<Eigen::VectorXd>(dz + b.offset, b.size) =
        -lin.fz[k].lu().solve(lin.fx[k] * element_values(b.element, dx_free));
  }
}

Eigen::VectorXd FemModel::internal_error_share() const {
  Eigen::VectorXd share(num_internal_);
  MaterialResponse resp;
  const auto rest_norm = [&](const MaterialTerm& term, int e) {
    MaterialPoint mp;
    mp.q = term.q.col(e).data();
    mp.state = term.state.size() ? term.state.col(e).data() : nullptr;
    mp.element = e;
    resp.dPdF.setZero();
    return term.model->evaluate(mp, kStress | kTangent, resp) ? resp.dPdF.norm() : 0.0;
  };
  for (const InternalBlock& b : internal_blocks_) {
    double elastic = 0;
    for (const MaterialTerm& term : terms_)
      if (!term.model->is_viscous() && term.model->internal_size() == 0 &&
          !term.model->needs_rest_tangent())
        elastic += rest_norm(term, b.element);
    const double branch = rest_norm(terms_[b.term], b.element);
    share.segment(b.offset, b.size)
        .setConstant(elastic > 0 ? std::min(1.0, branch / elastic) : 1.0);
  }
  return share;
}

void FemModel::relaxed_internal_change_transpose(const Eigen::Matrix3Xd& x, const double* lz,
                                                 double* out_free) const {
  if (internal_blocks_.empty()) return;
  const InternalLinearisation lin = relaxed_linearisation(x);
  for (size_t k = 0; k < internal_blocks_.size(); ++k) {
    const InternalBlock& b = internal_blocks_[k];
    const Eigen::Map<const Eigen::VectorXd> l(lz + b.offset, b.size);
    add_element_values(b.element, -lin.fx[k].transpose() * lin.fz[k].transpose().lu().solve(l),
                       out_free);
  }
}

bool FemModel::linearise_internal(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd&,
                                  const double* z, unsigned request,
                                  InternalLinearisation& out) const {
  const size_t nb = internal_blocks_.size();
  out.rate.resize(num_internal_);
  const bool tangent = request & kTangent, params = request & kParamDerivative;
  if (tangent) {
    out.Kxz.resize(nb);
    out.coupled.resize(nb);
    out.fx.resize(nb);
    out.fz.resize(nb);
  }
  if (params) out.fq.resize(nb);
  if (static_cast<int>(out.evolution.size()) < thread_count()) {
    out.evolution.resize(thread_count());
    out.response.resize(thread_count());
  }
  int failed = static_cast<int>(nb);
#pragma omp parallel for schedule(static) reduction(min : failed) if (nb >= kParallelMin)
  for (int k = 0; k < static_cast<int>(nb); ++k) {
    const InternalBlock& b = internal_blocks_[k];
    const Material& model = *terms_[b.term].model;
    const MaterialPoint mp = internal_point(b, x, z);
    InternalResponse& ir = out.evolution[thread_index()];
    model.evolve(mp, request, ir);
    out.rate.segment(b.offset, b.size) = ir.rate;
    if (params) out.fq[k] = ir.dq;
    if (!tangent) continue;
    MaterialResponse& resp = out.response[thread_index()];
    if (!model.evaluate(mp, kStress | kTangent, resp)) {
      failed = std::min(failed, k);
      continue;
    }
    // r_e = V P G: ∂r_e/∂z_j = V (∂P/∂z_j) G; F = x_e Gᵀ: ∂F_ij/∂x_(a,k) = δ_ik G_ja.
    const TetElement& el = elements_[b.element];
    out.Kxz[k].resize(12, b.size);
    for (int j = 0; j < b.size; ++j) {
      const Eigen::Map<const Mat3> dP(resp.dPdz.col(j).data());
      const Eigen::Matrix<double, 3, 4> f = el.volume * dP * el.G;
      out.Kxz[k].col(j) = Eigen::Map<const Eigen::Matrix<double, 12, 1>>(f.data());
    }
    out.coupled[k] = !out.Kxz[k].isZero(0);
    out.fx[k].resize(b.size, 12);
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i)
        out.fx[k].col(3 * a + i).noalias() = ir.dF.col(i) * el.G(0, a) +
                                             ir.dF.col(i + 3) * el.G(1, a) +
                                             ir.dF.col(i + 6) * el.G(2, a);
    out.fz[k] = ir.dz;
  }
  return failed == static_cast<int>(nb);
}

}  // namespace kelvin
