#include "adjoint/evaluation_plan.hpp"

namespace kelvin {

int EvaluationPlan::order_cap(const FemModel& model, const IntegratorOptions& options, double t_end,
                              const Eigen::VectorXd& x0, const Eigen::VectorXd& v0,
                              double tolerance_scale) {
  if (order_choice_.max_order == 0 || order_scale_ != tolerance_scale) {
    order_choice_ = choose_max_order(model, options, 0.0, t_end, x0, v0);
    order_scale_ = tolerance_scale;
  }
  return order_choice_.max_order;
}

bool EvaluationPlan::plan_segments(long steps, long budget, double duration,
                                   double tolerance_scale) {
  planned_steps_ = steps;
  planned_scale_ = tolerance_scale;
  if (steps < budget) {
    segment_ = 0;
    return false;
  }
  const long per_segment = std::max(budget / 2, 1L);
  segment_ = duration / static_cast<double>((steps + per_segment - 1) / per_segment);
  return true;
}

}  // namespace kelvin
