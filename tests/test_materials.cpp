// Constitutive models: derivatives against finite differences at random, compressed,
// stretched and nearly inverted states; known closed forms; model equivalences.
#include <gtest/gtest.h>

#include <cfloat>

#include "materials/derivative_check.hpp"
#include "materials/material.hpp"

using namespace kelvin;

namespace {

void expect_all_pass(const std::string& model, const std::vector<double>& q) {
  auto m = create_builtin_material(model);
  ASSERT_TRUE(m) << model;
  const auto checks = check_material_derivatives(*m, q);
  ASSERT_FALSE(checks.empty());
  for (const auto& c : checks)
    EXPECT_TRUE(c.passed()) << model << ": " << c.what << " at " << c.state << " relative error "
                            << c.error << " > " << c.tolerance;
}

}  // namespace

TEST(Materials, NeoHookeanDerivativesMatchFiniteDifferences) {
  expect_all_pass("neo-hookean", {2.5e4, 1.0e4});
}

TEST(Materials, NewtonianDerivativesMatchFiniteDifferences) {
  expect_all_pass("newtonian", {3.0});
}

TEST(Materials, PowerLawDerivativesMatchFiniteDifferences) {
  expect_all_pass("power-law", {12.0, 0.6});
  expect_all_pass("power-law", {12.0, 1.4});
}

TEST(Materials, NeoHookeanMatchesLinearElasticityAtSmallStrain) {
  // σ ≈ λ tr(ε) I + 2 μ ε for F = I + ε with ‖ε‖ ≪ 1.
  auto m = create_builtin_material("neo-hookean");
  const double q[] = {3e4, 1e4};
  Mat3 eps;
  eps << 1, 0.3, -0.2, 0.3, -0.5, 0.1, -0.2, 0.1, 0.4;
  eps *= 1e-7;
  MaterialPoint p;
  p.F = Mat3::Identity() + eps;
  p.q = q;
  MaterialResponse r;
  ASSERT_TRUE(m->evaluate(p, kStress, r));
  const Mat3 linear = q[0] * eps.trace() * Mat3::Identity() + 2 * q[1] * eps;
  EXPECT_LT((r.P - linear).norm() / linear.norm(), 1e-6);
}

TEST(Materials, NeoHookeanUniaxialClosedForm) {
  // Principal stretches (a, b, b): P₁₁ = λ/2 (J² − 1)/a + μ (a − 1/a), J = a b².
  auto m = create_builtin_material("neo-hookean");
  const double lambda = 2e4, mu = 7e3, a = 1.3, b = 0.9, J = a * b * b;
  const double q[] = {lambda, mu};
  MaterialPoint p;
  p.F = Eigen::Vector3d(a, b, b).asDiagonal();
  p.q = q;
  MaterialResponse r;
  ASSERT_TRUE(m->evaluate(p, kStress | kEnergy, r));
  EXPECT_NEAR(r.P(0, 0), lambda / 2 * (J * J - 1) / a + mu * (a - 1 / a), 1e-9 * mu);
  EXPECT_NEAR(r.P(1, 1), lambda / 2 * (J * J - 1) / b + mu * (b - 1 / b), 1e-9 * mu);
  EXPECT_NEAR(r.P(0, 1), 0.0, 1e-12 * mu);
  const double psi = lambda / 2 * ((J * J - 1) / 2 - std::log(J)) +
                     mu / 2 * (a * a + 2 * b * b - 3 - 2 * std::log(J));
  EXPECT_NEAR(r.energy, psi, 1e-12 * mu);
}

TEST(Materials, NeoHookeanRefusesInvertedElements) {
  auto m = create_builtin_material("neo-hookean");
  const double q[] = {1e4, 1e4};
  MaterialPoint p;
  p.F = Eigen::Vector3d(-0.5, 1, 1).asDiagonal();
  p.q = q;
  MaterialResponse r;
  EXPECT_FALSE(m->evaluate(p, kStress, r));
}

TEST(Materials, NewtonianShearStressClosedForm) {
  // Simple shear rate at F = I: L = γ̇ e₁⊗e₂, σ₁₂ = ν γ̇.
  auto m = create_builtin_material("newtonian");
  const double q[] = {4.0};
  MaterialPoint p;
  p.Fdot(0, 1) = 2.5;
  p.q = q;
  MaterialResponse r;
  ASSERT_TRUE(m->evaluate(p, kStress, r));
  EXPECT_NEAR(r.P(0, 1), 10.0, 1e-12);
  EXPECT_NEAR(r.P(1, 0), 10.0, 1e-12);
}

TEST(Materials, PowerLawWithUnitIndexEqualsNewtonianExactly) {
  auto pl = create_builtin_material("power-law");
  auto nt = create_builtin_material("newtonian");
  const double qp[] = {7.0, 1.0}, qn[] = {7.0};
  for (const auto& s : material_test_states({})) {
    MaterialPoint p;
    p.F = s.F;
    p.Fdot = s.Fdot;
    MaterialResponse a, b;
    p.q = qp;
    ASSERT_TRUE(pl->evaluate(p, kStress | kTangent | kRateTangent, a));
    p.q = qn;
    ASSERT_TRUE(nt->evaluate(p, kStress | kTangent | kRateTangent, b));
    EXPECT_EQ((a.P - b.P).norm(), 0.0) << s.label;
    EXPECT_LT((a.dPdF - b.dPdF).norm(), 1e-14 * b.dPdF.norm()) << s.label;
    EXPECT_LT((a.dPdFdot - b.dPdFdot).norm(), 1e-14 * b.dPdFdot.norm()) << s.label;
  }
}

TEST(Materials, PowerLawContributesNothingAtRest) {
  // Real2Sim's DBL_MIN rule: ‖∇v‖ ≤ DBL_MIN gives zero stress and tangents, even for h < 1.
  auto m = create_builtin_material("power-law");
  const double q[] = {7.0, 0.5};
  MaterialPoint p;
  p.F = Eigen::Vector3d(1.1, 0.9, 1.0).asDiagonal();
  p.Fdot(0, 0) = DBL_MIN / 10;
  p.q = q;
  MaterialResponse r;
  r.P.setOnes();
  r.dPdFdot.setOnes();
  ASSERT_TRUE(m->evaluate(p, kStress | kRateTangent, r));
  EXPECT_EQ(r.P.norm(), 0.0);
  EXPECT_EQ(r.dPdFdot.norm(), 0.0);
}

TEST(Materials, RegistryListsBuiltins) {
  const auto names = builtin_material_names();
  for (const char* n : {"neo-hookean", "newtonian", "power-law"})
    EXPECT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
  EXPECT_EQ(create_builtin_material("no-such-model"), nullptr);
}
