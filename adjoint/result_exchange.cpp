#include "adjoint/result_exchange.hpp"

namespace kelvin {

static_assert(std::is_trivially_copyable_v<IntegratorStats>);
static_assert(std::is_trivially_copyable_v<OrderChoice>);
static_assert(std::is_trivially_copyable_v<ResidualSample>);

namespace {

/// Every field, in one order for the writer and the reader.
template <class Bytes, class Result>
void fields(Bytes& io, Result& r) {
  io(r.ok);
  io(r.error);
  io(r.t_reached);
  io(r.t_furthest);
  io(r.phi_per_marker);
  io(r.phi_targets);
  io(r.phi);
  io(r.rms);
  io(r.gradient);
  io(r.dphi_dtheta);
  io(r.forward_stats);
  io(r.backward_stats);
  io(r.backward_steps);
  io(r.segments);
  io(r.seconds);
}

template <class Bytes, class System>
void gauss_newton_fields(Bytes& io, System& g) {
  io(g.ok);
  io(g.error);
  io(g.residual);
  io(g.jacobian);
  each_of(io, g.samples, [](auto& bytes, auto& sample) { bytes(sample); });
  io(g.rtol);
}

}  // namespace

void put(ByteWriter& out, const ExperimentResult& r) {
  fields(out, r);
}
void get(ByteReader& in, ExperimentResult& r) {
  fields(in, r);
}

void put(ByteWriter& out, const EvaluationPlan& plan) {
  EvaluationPlan::fields(out, plan);
}
void get(ByteReader& in, EvaluationPlan& plan) {
  EvaluationPlan::fields(in, plan);
}

void put(ByteWriter& out, const GaussNewtonSystem& g) {
  gauss_newton_fields(out, g);
}
void get(ByteReader& in, GaussNewtonSystem& g) {
  gauss_newton_fields(in, g);
}

}  // namespace kelvin
