// IDAS's local error test must not depend on where a body is meshed: scanned
// specimens and captured markers usually sit in camera or scanner coordinates,
// metres from the origin. A viscous cantilever creeping down under gravity from
// rest is integrated at the origin and 5 m away. Slow motion is where the position
// tolerance rules the steps; measured from the origin it would be rtol × 5 m = 5 mm
// for a 0.7 mm sag (before the fix: 125 and 115 steps, motions 1.6e-7 m apart).
#include <gtest/gtest.h>

#include <vector>

#include "tests/cantilever_fixture.hpp"

namespace kelvin::test {
namespace {

struct Sag {
  std::vector<double> tip;  // tip deflection (m) at the samples
  long steps = 0;
};

Sag sag_from_rest(const Eigen::Vector3d& origin, double rtol) {
  const Eigen::VectorXd nu = Eigen::VectorXd::Constant(1, 1e6);  // Pa s: creeps over ~0.1 s
  Beam b = make_beam(1, kG, {{create_builtin_material("newtonian"), nu, {}}}, origin);
  IntegratorOptions opt;
  opt.rtol = rtol;
  opt.atol = 1e-10;
  IdasIntegrator ida(*b.model, opt);
  Eigen::VectorXd x0(b.model->num_dofs());
  b.model->restrict(b.mesh.nodes, x0.data());
  ida.initialize(0.0, x0, Eigen::VectorXd::Zero(x0.size()));
  Sag s;
  const double duration = 0.1;
  for (int k = 1; k <= 20; ++k) {
    const double t = duration * k / 20;
    EXPECT_TRUE(ida.advance_to(t, duration)) << ida.error();
    s.tip.push_back(tip_deflection(b, ida.positions()));
  }
  s.steps = ida.stats().steps;
  return s;
}

TEST(ErrorWeights, TranslatingTheBodyChangesNeitherTheStepsNorTheMotion) {
  const double rtol = 1e-3;
  const Sag here = sag_from_rest(Eigen::Vector3d::Zero(), rtol);
  const Sag far = sag_from_rest(Eigen::Vector3d(5, -3, 4), rtol);
  double peak = 0, worst = 0;
  for (size_t k = 0; k < here.tip.size(); ++k) {
    peak = std::max(peak, std::abs(here.tip[k]));
    worst = std::max(worst, std::abs(far.tip[k] - here.tip[k]));
  }
  ASSERT_GT(peak, 5e-4);  // the tip creeps down by most of a millimetre
  // Positions 5 m from the origin carry round-off 1e-15 m, which might change a
  // step; with the same steps the motions agree to round-off (1e-13 m measured).
  EXPECT_NEAR(far.steps, here.steps, 0.02 * here.steps);
  EXPECT_LT(worst, 0.01 * rtol * peak)
      << "steps at the origin " << here.steps << ", 5 m away " << far.steps;
}

}  // namespace
}  // namespace kelvin::test
