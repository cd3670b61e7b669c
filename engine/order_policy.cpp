#include "engine/order_policy.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "base/error.hpp"

namespace kelvin {
namespace {

/// Steps a cap takes over [t0, t1], or −(steps taken) when it failed or needed more
/// than `budget` (> 0).
long probe(const FemModel& model, IntegratorOptions options, int cap, double t0, double t1,
           const Eigen::VectorXd& x0, const Eigen::VectorXd& v0, long budget) {
  options.max_order = cap;
  IdasIntegrator integ(model, options);
  try {
    integ.initialize(t0, x0, v0);
  } catch (const Error&) {
    return -1;
  }
  const bool ok = integ.advance_to(t1, t1, budget);
  const long steps = integ.stats().steps;
  return ok ? steps : -std::max(steps, 1L);
}

}  // namespace

OrderChoice choose_max_order(const FemModel& model, const IntegratorOptions& options, double t0,
                             double t_end, const Eigen::VectorXd& x0, const Eigen::VectorXd& v0) {
  OrderChoice c;
  c.window = kOrderProbeShare * (t_end - t0);
  c.max_order = kOrderCandidates.front();
  if (!(c.window > 0)) return c;
  long best = 0;
  for (int cap : kOrderCandidates) {
    // A tie goes to the higher cap: budget = best steps, and "more than" loses.
    const long steps =
        probe(model, options, cap, t0, t0 + c.window, x0, v0, best > 0 ? best + 1 : 0);
    c.steps[cap] = steps;
    if (steps <= 0 || (best > 0 && steps > best)) break;
    best = steps;
    c.max_order = cap;
  }
  return c;
}

std::string OrderChoice::summary() const {
  std::string probes;
  for (int cap : kOrderCandidates) {
    if (steps[cap] == 0) continue;
    if (!probes.empty()) probes += ", ";
    probes += steps[cap] > 0 ? fmt::format("order {}: {} steps", cap, steps[cap])
                             : fmt::format("order {}: abandoned after {}", cap, -steps[cap]);
  }
  return fmt::format("BDF order up to {} (probe over the first {:.3g} s: {})", max_order, window,
                     probes);
}

}  // namespace kelvin
