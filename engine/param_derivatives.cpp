#include "engine/param_derivatives.hpp"

#include <fmt/format.h>

#include "base/error.hpp"

namespace kelvin {
namespace {

/// dP/dq of one elastic term at F, for the given element.
Mat9X elastic_param_derivative(const MaterialTerm& term, int e, const Mat3& F) {
  MaterialPoint mp;
  mp.F = F;
  mp.q = term.q.col(e).data();
  mp.state = term.state.size() ? term.state.col(e).data() : nullptr;
  mp.element = e;
  MaterialResponse resp;
  if (!term.model->evaluate(mp, kParamDerivative, resp))
    throw Error(fmt::format("material '{}' cannot evaluate dP/dq near rest in element {}",
                            term.model->name(), e));
  return resp.dPdq;
}

/// ∂C₀/∂q_k = ∂(dP/dq_k)/∂F at F = I, by central differences extrapolated to h → 0.
Mat9 rest_tangent_param_derivative(const MaterialTerm& term, int e, int k) {
  auto central = [&](double h) {
    Mat9 D;
    for (int b = 0; b < 9; ++b) {
      Mat3 E = Mat3::Zero();
      E(b % 3, b / 3) = h;
      const Mat3 I = Mat3::Identity();
      D.col(b) = (elastic_param_derivative(term, e, I + E).col(k) -
                  elastic_param_derivative(term, e, I - E).col(k)) /
                 (2 * h);
    }
    return D;
  };
  const double h = 1e-3;
  return (4 * central(h / 2) - central(h)) / 3;
}

}  // namespace

ParamDerivatives::ParamDerivatives(const FemModel& model, std::vector<ParamSlot> slots)
    : model_(model), slots_(std::move(slots)) {
  const auto& terms = model_.terms();
  for (int t = 0; t < static_cast<int>(terms.size()); ++t)
    if (terms[t].model->needs_rest_tangent()) rest_tangent_users_.push_back(t);
  for (const auto& s : slots_) {
    if (s.is_material() && (s.term >= static_cast<int>(terms.size()) ||
                            s.index >= static_cast<int>(terms[s.term].model->params().size())))
      throw Error("parameter slot refers to a material parameter that does not exist");
    if (s.is_clamp() && (s.clamp >= static_cast<int>(model_.clamps().size()) ||
                         !model_.clamps()[s.clamp].compliant()))
      throw Error("parameter slot refers to a compliance of a clamp that is not compliant");
    if (s.is_force() && (s.force > 2 || s.index >= model_.body_force().knots()))
      throw Error("parameter slot refers to a body-force knot the model does not have");
  }
  update();
}

void ParamDerivatives::update() {
  dC0_.assign(slots_.size(), {});
  if (rest_tangent_users_.empty()) return;
  const auto& terms = model_.terms();
  const int ne = model_.mesh().num_tets();
  for (size_t s = 0; s < slots_.size(); ++s) {
    if (!slots_[s].is_material() || terms[slots_[s].term].model->is_viscous()) continue;
    dC0_[s].resize(ne);
    for (int e = 0; e < ne; ++e)
      dC0_[s][e] = rest_tangent_param_derivative(terms[slots_[s].term], e, slots_[s].index);
  }
}

bool ParamDerivatives::for_each(double t, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                const Eigen::Matrix3Xd& a, const Visitor& visit,
                                const ElementTangents* cached, const double* z,
                                const InternalVisitor& visit_internal) const {
  const auto& terms = model_.terms();
  const int nt = static_cast<int>(terms.size());
  const auto& elements = model_.elements();
  MaterialPoint mp;
  MaterialResponse resp;
  std::vector<Mat9X> evaluated(nt);
  std::vector<const Mat9X*> dPdq(nt);
  if (cached && cached->dPdq.empty()) cached = nullptr;
  std::vector<char> needed(nt, 0);
  for (const auto& s : slots_)
    if (s.is_material()) needed[s.term] = 1;
  // A body-force knot's hat at t: at most two per axis are non-zero.
  std::vector<double> hat(slots_.size(), 0.0);
  for (std::size_t s = 0; s < slots_.size(); ++s)
    if (slots_[s].is_force()) hat[s] = model_.body_force().hat(slots_[s].index, t);
  Eigen::Matrix<double, 3, 4> xe, ve, ae;
  Vec12 dR;
  for (int e = 0; e < model_.mesh().num_tets(); ++e) {
    const TetElement& el = elements[e];
    for (int n = 0; n < 4; ++n) {
      xe.col(n) = x.col(el.nodes[n]);
      ve.col(n) = v.col(el.nodes[n]);
      ae.col(n) = a.col(el.nodes[n]);
    }
    mp.F = xe * el.G.transpose();
    mp.Fdot = ve * el.G.transpose();
    mp.element = e;
    mp.rest_tangent = model_.rest_tangent(e);
    double mass_damping = 0;
    for (int t = 0; t < nt; ++t) {
      mp.q = terms[t].q.col(e).data();
      mp.state = terms[t].state.size() ? terms[t].state.col(e).data() : nullptr;
      const int m = terms[t].model->internal_size();
      mp.internal =
          m > 0 && z ? z + model_.internal_blocks()[model_.internal_block(t, e)].offset : nullptr;
      if (const int k = terms[t].model->mass_damping_param(); k >= 0) mass_damping += mp.q[k];
      if (!needed[t]) continue;
      if (cached) {
        dPdq[t] = &cached->dPdq[e][t];
        continue;
      }
      if (m > 0 && !z) {  // relaxed: no stress, and none of its derivatives
        evaluated[t].setZero(9, static_cast<int>(terms[t].model->params().size()));
        dPdq[t] = &evaluated[t];
        continue;
      }
      if (!terms[t].model->evaluate(mp, kParamDerivative, resp)) return false;
      evaluated[t] = resp.dPdq;
      dPdq[t] = &evaluated[t];
    }
    for (int s = 0; s < static_cast<int>(slots_.size()); ++s) {
      const ParamSlot& slot = slots_[s];
      if (slot.is_clamp()) continue;  // below, face by face
      if (slot.is_force()) {
        // The load ρ_e V_e/4 φₖ(t) on each node's component `force`, subtracted in R.
        const double w = hat[s];
        if (w == 0) continue;
        dR.setZero();
        for (int n = 0; n < 4; ++n)
          dR[3 * n + slot.force] = -w * model_.density()[e] * el.volume / 4;
      } else if (slot.is_density()) {
        // M_e is linear in ρ_e: ∂R/∂ρ_e = (M_e/ρ_e)(a − g + α₀ v), gravity being M g.
        Eigen::Matrix<double, 3, 4> rhs = ae + mass_damping * ve;
        rhs.colwise() -= model_.gravity();
        dR = (model_.element_mass_times(e, rhs) / model_.density()[e]).reshaped();
      } else {
        const Material& m = *terms[slot.term].model;
        Mat3 dP = Eigen::Map<const Mat3>(dPdq[slot.term]->col(slot.index).data());
        if (!dC0_[s].empty())
          for (int t : rest_tangent_users_) {
            // Stresses linear in C₀: evaluating with ∂C₀/∂q in its place gives ∂P/∂q.
            MaterialPoint mq = mp;
            mq.q = terms[t].q.col(e).data();
            mq.state = terms[t].state.size() ? terms[t].state.col(e).data() : nullptr;
            mq.rest_tangent = &dC0_[s][e];
            if (!terms[t].model->evaluate(mq, kStress, resp)) return false;
            dP += resp.P;
          }
        dR = (el.volume * dP * el.G).reshaped();
        if (slot.index == m.mass_damping_param()) dR += model_.element_mass_times(e, ve).reshaped();
        if (const int size = m.internal_size(); size > 0 && z && visit_internal) {
          MaterialPoint mi = mp;
          mi.q = terms[slot.term].q.col(e).data();
          mi.state = terms[slot.term].state.size() ? terms[slot.term].state.col(e).data() : nullptr;
          const int block = model_.internal_block(slot.term, e);
          mi.internal = z + model_.internal_blocks()[block].offset;
          InternalResponse ir;
          m.evolve(mi, kParamDerivative, ir);
          visit_internal(block, s, -ir.dq.col(slot.index));
        }
      }
      visit(e, s, dR);
    }
  }
  for (int s = 0; s < static_cast<int>(slots_.size()); ++s)
    if (slots_[s].is_clamp()) clamp_compliance_derivative(t, x, v, s, visit);
  return true;
}

void ParamDerivatives::clamp_compliance_derivative(double t, const Eigen::Matrix3Xd& x,
                                                   const Eigen::Matrix3Xd& v, int s,
                                                   const Visitor& visit) const {
  // The pads' force Σ_b S_ab (g_b + τ ġ_b)/c, g = x − x̂: its c-derivative is
  // −Σ_b S_ab (g_b + τ ġ_b)/c².
  const ClampBinding& clamp = model_.clamps()[slots_[s].clamp];
  const RigidPose pose = clamp.motion->at(t);
  const double c2 = clamp.compliance * clamp.compliance;
  for (const ClampFace& f : model_.clamp_faces()) {
    if (f.clamp != slots_[s].clamp) continue;
    Eigen::Vector3d gap[3];
    for (int b = 0; b < 3; ++b) {
      const Eigen::Vector3d X = model_.mesh().nodes.col(f.nodes[b]);
      gap[b] = x.col(f.nodes[b]) - pose.position(X) +
               clamp.damping_time * (v.col(f.nodes[b]) - pose.velocity(X));
    }
    Vec12 dR = Vec12::Zero();
    for (int a = 0; a < 3; ++a)
      dR.segment<3>(3 * f.local[a]) = -face_product(f, a, [&](int b) { return gap[b]; }) / c2;
    visit(f.element, s, dR);
  }
}

}  // namespace kelvin
