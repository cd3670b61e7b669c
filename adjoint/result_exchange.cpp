#include "adjoint/result_exchange.hpp"

namespace kelvin {

static_assert(std::is_trivially_copyable_v<IntegratorStats>);
static_assert(std::is_trivially_copyable_v<OrderChoice>);

void put(ByteWriter& out, const ExperimentResult& r) {
  out.put(r.ok);
  out.put(r.error);
  out.put(r.t_reached);
  out.put(r.t_furthest);
  out.put(r.phi_per_marker);
  out.put(r.phi_targets);
  out.put(r.phi);
  out.put(r.rms);
  out.put(r.gradient);
  out.put(r.dphi_dtheta);
  out.put(r.forward_stats);
  out.put(r.backward_stats);
  out.put(r.backward_steps);
  out.put(r.segments);
  out.put(r.seconds);
}

void get(ByteReader& in, ExperimentResult& r) {
  in.get(r.ok);
  in.get(r.error);
  in.get(r.t_reached);
  in.get(r.t_furthest);
  in.get(r.phi_per_marker);
  in.get(r.phi_targets);
  in.get(r.phi);
  in.get(r.rms);
  in.get(r.gradient);
  in.get(r.dphi_dtheta);
  in.get(r.forward_stats);
  in.get(r.backward_stats);
  in.get(r.backward_steps);
  in.get(r.segments);
  in.get(r.seconds);
}

void put(ByteWriter& out, const EvaluationPlan& plan) {
  out.put(plan.segment_);
  out.put(plan.planned_scale_);
  out.put(plan.planned_steps_);
  out.put(plan.order_choice_);
  out.put(plan.order_scale_);
  out.put(plan.adjoint_peaks_);
}

void get(ByteReader& in, EvaluationPlan& plan) {
  in.get(plan.segment_);
  in.get(plan.planned_scale_);
  in.get(plan.planned_steps_);
  in.get(plan.order_choice_);
  in.get(plan.order_scale_);
  in.get(plan.adjoint_peaks_);
}

}  // namespace kelvin
