// The automatic BDF order cap (engine/order_policy.hpp): a lightly damped bar runs
// at the A-stable order's step count, not at the step count that orders 3–5 need to
// stay stable, and a strongly damped one keeps a higher order; both stay accurate
// against a tight reference.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "engine/markers.hpp"
#include "engine/order_policy.hpp"
#include "tests/test_support.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {
namespace {

/// A bar clamped at z = 0, shaken sideways at `frequency` from its static state,
/// with a marker at its tip: Newtonian viscosity ν on neo-Hookean (λ, μ).
std::string bar(double mu, double nu, double density, double length, double frequency) {
  return fmt::format(R"(
name: order-policy-bar
mesh: {{ generate: box, lo: [-0.01, -0.01, 0], hi: [0.01, 0.01, {}], element_size: 0.01 }}
material:
  density: {}
  elastic: {{ model: neo-hookean, lambda: 1.2e4, mu: {} }}
  viscous: {{ model: newtonian, nu: {} }}
gravity: [0, 0, -9.81]
initial: static
clamps:
  - name: base
    select: {{ plane: {{ axis: z, at: 0 }} }}
    motion:
      sinusoids:
        translation:
          - {{ amplitude: 0.005, frequency: {}, phase: -1.5707963267948966, direction: [1, 0, 0] }}
markers:
  rest:
    - {{ name: tip, at: [0, 0, {}] }}
    - {{ name: middle, at: [0.01, 0, {}] }}
time: {{ end: 0.4, output_rate: 200 }}
)",
                     length, density, mu, nu, frequency, length, length / 2);
}

struct Trajectory {
  long steps = 0;
  int order = 0;  // the cap used
  std::vector<Eigen::Matrix3Xd> markers;
};

/// The scenario integrated with rtol and the cap max_order (0 = auto), markers
/// sampled at its output frames.
Trajectory simulate(const Scenario& base, double rtol, int max_order) {
  Scenario s = base;
  s.solver.rtol = rtol;
  s.solver.atol = rtol * 1e-5;
  s.solver.max_order = max_order;
  auto model = build_model(s);
  Eigen::VectorXd x0, v0;
  initial_state(s, *model, x0, v0);
  IntegratorOptions o = integrator_options(s.solver);
  Trajectory r;
  if (o.max_order == 0) o.max_order = choose_max_order(*model, o, 0, s.time.end, x0, v0).max_order;
  r.order = o.max_order;
  IdasIntegrator ida(*model, o);
  ida.initialize(0, x0, v0);
  Eigen::Matrix3Xd x, v;
  const int frames = static_cast<int>(std::lround(s.time.end * s.time.output_rate));
  for (int k = 1; k <= frames; ++k) {
    const double t = k / s.time.output_rate;
    EXPECT_TRUE(ida.advance_to(t, s.time.end)) << ida.error();
    model->expand(t, ida.positions().data(), ida.velocities().data(), x, v);
    r.markers.push_back(marker_positions(s.mesh, s.markers.embedded, x));
  }
  r.steps = ida.stats().steps;
  return r;
}

double rms(const Trajectory& a, const Trajectory& b) {
  double sum = 0;
  for (size_t k = 0; k < a.markers.size(); ++k)
    sum += (a.markers[k] - b.markers[k]).colwise().squaredNorm().sum();
  return std::sqrt(sum / (a.markers.size() * a.markers[0].cols()));
}

Scenario load(const std::string& text, const std::string& name) {
  const auto dir = test::scratch("order-policy");
  test::write_text(dir / name, text);
  return load_scenario((dir / name).string());
}

}  // namespace

// Light damping (ν/μ = 3 µs): the bar's modes up to kHz have damping ratios below
// 7 %, inside BDF3–5's unstable wedges, so orders 3–5 are held to tiny steps.
TEST(OrderPolicy, ALightlyDampedBarRunsAtTheAStableOrder) {
  const Scenario s = load(bar(1.5e5, 0.5, 100, 0.15, 3), "light.yaml");
  const Trajectory reference = simulate(s, 1e-8, 5);
  const Trajectory automatic = simulate(s, 1e-4, 0), two = simulate(s, 1e-4, 2),
                   five = simulate(s, 1e-4, 5);
  EXPECT_EQ(automatic.order, 2);
  EXPECT_EQ(automatic.steps, two.steps);
  EXPECT_GT(five.steps, 2 * two.steps) << "order 5 is not held back here: the case tests nothing";
  EXPECT_LT(rms(automatic, reference), 0.05e-3);
}

// Strong damping (ν/μ = 67 µs, the bench bar's ratio): every mode above ~300 Hz
// is damped past BDF3's wedge, and a higher order takes fewer steps than order 2.
TEST(OrderPolicy, AStronglyDampedBarKeepsAHigherOrder) {
  const Scenario s = load(bar(3e5, 20, 1100, 0.05, 17), "strong.yaml");
  const Trajectory reference = simulate(s, 1e-8, 5);
  const Trajectory automatic = simulate(s, 1e-4, 0), two = simulate(s, 1e-4, 2);
  EXPECT_GE(automatic.order, 3);
  EXPECT_LT(automatic.steps, two.steps);
  EXPECT_LT(rms(automatic, reference), rms(two, reference));
}

}  // namespace kelvin
