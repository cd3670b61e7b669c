// The built-in material library beyond neo-Hookean and the viscous models:
// derivatives against finite differences (default and other parameters, plus
// repeated-stretch states for the SVD-based models), small-strain equivalences,
// rotation invariance and model-to-model reductions.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <random>

#include "materials/derivative_check.hpp"
#include "materials/material.hpp"
#include "materials/spline_material.hpp"

using namespace kelvin;

namespace {

const char* const kElastic[] = {"stable-neo-hookean", "corotational", "stvk",
                                "mooney-rivlin",      "spline",       "fiber",
                                "stiffening",         "fibre"};

std::vector<double> defaults(const Material& m) {
  std::vector<double> q;
  for (const auto& p : m.params()) q.push_back(p.default_value);
  return q;
}

/// Defaults, except for the extension terms, which are zero by default (nested):
/// a stress worth testing.
std::vector<double> test_parameters(const Material& m) {
  if (m.name() == "stiffening") return {1e5};
  if (m.name() == "fibre") return {5e4, 0.6, 1.1};
  return defaults(m);
}

void expect_all_pass(const std::string& model, std::vector<double> q = {},
                     double tolerance = 1e-6) {
  auto m = create_builtin_material(model);
  ASSERT_TRUE(m) << model;
  if (q.empty()) q = defaults(*m);
  ASSERT_EQ(q.size(), m->params().size()) << model;
  MaterialCheckOptions opt;
  opt.tolerance = tolerance;
  const auto checks = check_material_derivatives(*m, q, opt);
  ASSERT_FALSE(checks.empty());
  for (const auto& c : checks)
    EXPECT_TRUE(c.passed()) << model << ": " << c.what << " at " << c.state << " relative error "
                            << c.error << " > " << c.tolerance;
}

MaterialResponse eval(const Material& m, const Mat3& F, const std::vector<double>& q,
                      unsigned request = kStress, const Mat3& Fdot = Mat3::Zero(),
                      const double* state = nullptr) {
  MaterialPoint p;
  p.F = F;
  p.Fdot = Fdot;
  p.q = q.data();
  p.state = state;
  MaterialResponse r;
  EXPECT_TRUE(m.evaluate(p, request, r)) << m.name();
  return r;
}

/// Central-difference dP/dF at one F, step h (for states the shared checker does not visit).
double tangent_error(const Material& m, const Mat3& F, const std::vector<double>& q) {
  const Mat9 K = eval(m, F, q, kStress | kTangent).dPdF;
  Mat9 fd;
  const double h = 1e-6;
  for (int k = 0; k < 9; ++k) {
    Mat3 Fp = F, Fm = F;
    Fp(k % 3, k / 3) += h;
    Fm(k % 3, k / 3) -= h;
    const Mat3 d = (eval(m, Fp, q).P - eval(m, Fm, q).P) / (2 * h);
    fd.col(k) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(d.data());
  }
  return (K - fd).norm() / K.norm();
}

Mat3 rotation(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  return Eigen::AngleAxisd(3 * u(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized())
      .toRotationMatrix();
}

Mat3 random_matrix(std::mt19937_64& rng, double scale) {
  std::uniform_real_distribution<double> u(-1, 1);
  Mat3 A;
  for (int k = 0; k < 9; ++k) A(k % 3, k / 3) = scale * u(rng);
  return A;
}

double rel(const Mat3& a, const Mat3& b) {
  return (a - b).norm() / b.norm();
}

}  // namespace

TEST(MaterialLibrary, AllModelsRegistered) {
  for (const char* name : kElastic) {
    auto m = create_builtin_material(name);
    ASSERT_TRUE(m) << name;
    EXPECT_EQ(m->name(), name);
    EXPECT_TRUE(m->has_energy()) << name;
    EXPECT_FALSE(m->is_viscous()) << name;
  }
  auto d = create_builtin_material("strain-damping");
  ASSERT_TRUE(d);
  EXPECT_TRUE(d->is_viscous());
  for (const char* name : kElastic)
    for (const auto& p : create_builtin_material(name)->params()) {
      EXPECT_FALSE(p.name.empty());
      EXPECT_FALSE(p.unit.empty()) << name << "." << p.name;
      EXPECT_FALSE(p.description.empty()) << name << "." << p.name;
      EXPECT_GE(p.default_value, p.lower) << name << "." << p.name;
      EXPECT_LE(p.default_value, p.upper) << name << "." << p.name;
    }
}

TEST(MaterialLibrary, StableNeoHookeanDerivatives) {
  expect_all_pass("stable-neo-hookean");
  expect_all_pass("stable-neo-hookean", {2.5e4, 1e4});
  expect_all_pass("stable-neo-hookean", {1e6, 3e3});  // nearly incompressible
}

TEST(MaterialLibrary, StableNeoHookeanEvaluatesInvertedElements) {
  auto m = create_builtin_material("stable-neo-hookean");
  const std::vector<double> q = {2e4, 1e4};
  const Mat3 F = Eigen::Vector3d(-0.5, 1, 1).asDiagonal();
  const auto r = eval(*m, F, q, kStress | kTangent | kEnergy);
  EXPECT_TRUE(r.P.allFinite());
  EXPECT_LT(tangent_error(*m, F, q), 1e-6);
  // The volumetric term pushes the inverted element back: stress along the
  // inverted axis opposes further inversion (P₀₀ < 0 means d Ψ/dF₀₀ < 0 at F₀₀ < 0).
  EXPECT_LT(r.P(0, 0), 0);
  // Even a collapsed element (F = 0.05 R, J ≈ 1e-4) has an exact tangent.
  EXPECT_LT(tangent_error(*m, 0.05 * Mat3::Identity(), q), 1e-6);
  EXPECT_LT(tangent_error(*m, Eigen::Vector3d(0.3, -0.2, 0.9).asDiagonal(), q), 1e-6);
}

TEST(MaterialLibrary, CorotationalDerivatives) {
  expect_all_pass("corotational");
  expect_all_pass("corotational", {3e4, 5e3});
}

TEST(MaterialLibrary, StVKDerivatives) {
  expect_all_pass("stvk");
  expect_all_pass("stvk", {4e4, 2e3});
}

TEST(MaterialLibrary, MooneyRivlinDerivatives) {
  expect_all_pass("mooney-rivlin");
  expect_all_pass("mooney-rivlin", {8e3, -1e3, 5e4});
  expect_all_pass("mooney-rivlin", {2e3, 0, 1e4});
}

TEST(MaterialLibrary, FiberDerivatives) {
  expect_all_pass("fiber");
  expect_all_pass("fiber", {2e4, 5e3, 3e4, 0.5});
  expect_all_pass("fiber", {2e4, 5e3, 3e4, 0.0});  // quadratic limit
}

// The extension terms the diagnosis adds to a nominal model (nested at zero).
TEST(MaterialLibrary, ExtensionTermDerivatives) {
  expect_all_pass("stiffening", {1.5e5});
  expect_all_pass("fibre", {8e4, 0.7853981633974483, 1.5707963267948966});  // a = (0, 1, 1)/√2
  expect_all_pass("fibre", {3e4, 0.3, -2.0});
}

TEST(MaterialLibrary, ExtensionTermsHaveTheirClosedForms) {
  std::mt19937_64 rng(11);
  const Mat3 F = Mat3::Identity() + random_matrix(rng, 0.3);
  const double J = F.determinant(), I1 = F.squaredNorm();
  // Ψ = c₂ (I₁ − 3 − 2 ln J)², P = 4 c₂ (I₁ − 3 − 2 ln J)(F − F⁻ᵀ).
  auto s = create_builtin_material("stiffening");
  const double c2 = 1.5e5, a = I1 - 3 - 2 * std::log(J);
  const MaterialResponse rs = eval(*s, F, {c2}, kStress | kEnergy);
  EXPECT_NEAR(rs.energy, c2 * a * a, 1e-9 * c2);
  EXPECT_LT(rel(rs.P, 4 * c2 * a * (F - Mat3(F.inverse().transpose()))), 1e-12);
  // Nothing at rest, and nothing to first order in the strain.
  EXPECT_EQ(eval(*s, Mat3::Identity(), {c2}).P.norm(), 0.0);
  // Ψ = k/2 (|F a|² − 1)², a = (0, 1, 1)/√2 at θ = π/4, φ = π/2.
  auto f = create_builtin_material("fibre");
  const std::vector<double> q = {8e4, M_PI / 4, M_PI / 2};
  const Eigen::Vector3d dir = Eigen::Vector3d(0, 1, 1).normalized();
  const double x = (F * dir).squaredNorm() - 1;
  const MaterialResponse rf = eval(*f, F, q, kStress | kEnergy);
  EXPECT_NEAR(rf.energy, 0.5 * q[0] * x * x, 1e-9 * q[0]);
  EXPECT_LT(rel(rf.P, 2 * q[0] * x * (F * dir) * dir.transpose()), 1e-12);
  // Drag has no stress: its force is the engine's c M v.
  auto d = create_builtin_material("drag");
  ASSERT_TRUE(d->is_viscous());
  EXPECT_EQ(d->mass_damping_param(), 0);
  EXPECT_EQ(eval(*d, F, {2.0}, kStress, random_matrix(rng, 1.0)).P.norm(), 0.0);
}

TEST(MaterialLibrary, FiberDerivativesAlongAnotherDirection) {
  auto m = create_builtin_material("fiber");
  const std::vector<double> q = {2e4, 5e3, 3e4, 0.8};
  const double a[] = {1, 2, -0.5};  // not normalised on purpose
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 5; ++trial) {
    const Mat3 F = Mat3::Identity() + random_matrix(rng, 0.3);
    MaterialPoint p;
    p.F = F;
    p.q = q.data();
    p.state = a;
    MaterialResponse r;
    ASSERT_TRUE(m->evaluate(p, kStress | kTangent | kEnergy, r));
    Mat9 fd;
    for (int k = 0; k < 9; ++k) {
      MaterialResponse rp, rm;
      MaterialPoint pp = p, pm = p;
      pp.F(k % 3, k / 3) += 1e-6;
      pm.F(k % 3, k / 3) -= 1e-6;
      m->evaluate(pp, kStress | kEnergy, rp);
      m->evaluate(pm, kStress | kEnergy, rm);
      const Mat3 d = (rp.P - rm.P) / 2e-6;
      fd.col(k) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(d.data());
      EXPECT_NEAR((rp.energy - rm.energy) / 2e-6, r.P(k % 3, k / 3), 1e-5 * r.P.norm());
    }
    EXPECT_LT((fd - r.dPdF).norm() / r.dPdF.norm(), 1e-6);
  }
}

TEST(MaterialLibrary, StrainDampingDerivatives) {
  expect_all_pass("strain-damping");
  expect_all_pass("strain-damping", {2.0, 1.5, 3.0});
  expect_all_pass("strain-damping", {2.0, -0.5, 4.0});
}

TEST(MaterialLibrary, SplineDerivatives) {
  expect_all_pass("spline");
  expect_all_pass("spline", SplineMaterial::neo_hookean_values(3e4, 5e3));
}

TEST(MaterialLibrary, SplineDerivativesWithArbitraryControlValues) {
  // Control values that are not neo-Hookean (the rest state then carries stress,
  // which the shared checker would flag, so check the derivatives directly).
  auto m = create_builtin_material("spline");
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> q = SplineMaterial::neo_hookean_values(2e4, 1e4);
  for (double& v : q) v += 3e3 * u(rng);
  for (const auto& s : material_test_states({})) {
    // Scaled off the knots: f'' jumps there, so a central difference straddling a
    // knot does not measure the (one-sided) tangent.
    const Mat3 F = 1.0123 * s.F;
    EXPECT_LT(tangent_error(*m, F, q), 1e-6) << s.label;
  }
}

TEST(MaterialLibrary, TangentsAtRepeatedStretches) {
  // Near-equal and exactly equal principal stretches: the divided differences of
  // the SVD-based tangent must stay finite and exact.
  std::mt19937_64 rng(3);
  const Mat3 R = rotation(rng), Q = rotation(rng);
  std::vector<Mat3> states = {
      Mat3::Identity() + 1e-4 * random_matrix(rng, 1.0),
      Mat3::Identity() + 1e-7 * random_matrix(rng, 1.0),
      R * Eigen::Vector3d(1.2, 1.2, 0.9).asDiagonal() * R.transpose(),
      R * Eigen::Vector3d(1.3, 0.8, 0.8).asDiagonal() * Q,
      R * Eigen::Vector3d(0.7, 0.7 + 1e-8, 0.7 - 1e-8).asDiagonal() * Q,
      R * Eigen::Vector3d(1.1, 1.1 + 3e-7, 1.4).asDiagonal() * Q,
  };
  for (const char* name : {"spline", "corotational"}) {
    auto m = create_builtin_material(name);
    std::vector<double> q = defaults(*m);
    for (const auto& F : states) EXPECT_LT(tangent_error(*m, F, q), 1e-6) << name << "\n" << F;
  }
  auto m = create_builtin_material("spline");
  const auto r = eval(*m, Mat3::Identity(), defaults(*m), kStress | kTangent);
  EXPECT_TRUE(r.dPdF.allFinite());
}

TEST(MaterialLibrary, SmallStrainAgreementOfNeoHookeanFamily) {
  const double lambda = 2.5e4, mu = 1e4;
  std::mt19937_64 rng(5);
  auto nh = create_builtin_material("neo-hookean");
  auto snh = create_builtin_material("stable-neo-hookean");
  auto mr = create_builtin_material("mooney-rivlin");
  auto co = create_builtin_material("corotational");
  auto sv = create_builtin_material("stvk");
  const double c10 = 0.3 * mu, c01 = 0.5 * mu - c10;  // 2 (c10 + c01) = μ
  for (int trial = 0; trial < 5; ++trial) {
    const Mat3 F = Mat3::Identity() + random_matrix(rng, 1e-4);
    const Mat3 ref = eval(*nh, F, {lambda, mu}).P;
    EXPECT_LT(rel(eval(*snh, F, {lambda, mu}).P, ref), 1e-3);
    EXPECT_LT(rel(eval(*mr, F, {c10, c01, lambda + 2 * mu / 3}).P, ref), 1e-3);
    EXPECT_LT(rel(eval(*sv, F, {lambda, mu}).P, ref), 1e-3);
    EXPECT_LT(rel(eval(*co, F, {lambda, mu}).P, ref), 1e-3);
  }
  // Identical rest tangents, not just nearby stresses.
  const Mat9 C0 = eval(*nh, Mat3::Identity(), {lambda, mu}, kTangent).dPdF;
  EXPECT_LT((eval(*snh, Mat3::Identity(), {lambda, mu}, kTangent).dPdF - C0).norm(),
            1e-8 * C0.norm());
  EXPECT_LT(
      (eval(*mr, Mat3::Identity(), {c10, c01, lambda + 2 * mu / 3}, kTangent).dPdF - C0).norm(),
      1e-8 * C0.norm());
}

TEST(MaterialLibrary, CorotationalMatchesLinearElasticityAndIsRotationInvariant) {
  const std::vector<double> q = {3e4, 1e4};
  auto m = create_builtin_material("corotational");
  Mat3 eps;
  eps << 1, 0.3, -0.2, 0.3, -0.5, 0.1, -0.2, 0.1, 0.4;
  eps *= 1e-6;
  const Mat3 linear = q[0] * eps.trace() * Mat3::Identity() + 2 * q[1] * eps;
  const Mat3 P = eval(*m, Mat3::Identity() + eps, q).P;
  EXPECT_LT(rel(P, linear), 1e-5);
  // Exact for a rotated symmetric stretch: P = R (2μ (S − I) + λ tr(S − I) I).
  std::mt19937_64 rng(9);
  for (int trial = 0; trial < 5; ++trial) {
    const Mat3 R = rotation(rng);
    Mat3 A = random_matrix(rng, 0.3);
    const Mat3 S = Mat3::Identity() + 0.5 * (A + A.transpose());
    const Mat3 expect = R * (2 * q[1] * (S - Mat3::Identity()) +
                             q[0] * (S - Mat3::Identity()).trace() * Mat3::Identity());
    EXPECT_LT(rel(eval(*m, R * S, q).P, expect), 1e-12);
    // Large rotation of a small strain: still linear in the corotated frame.
    EXPECT_LT(rel(eval(*m, R * (Mat3::Identity() + eps), q).P, R * linear), 1e-5);
  }
}

TEST(MaterialLibrary, MaxwellBranchStressAndEvolutionMatchFiniteDifferences) {
  // Away from its relaxed state the branch carries stress: dP/dF, dP/dz, dP/dq and
  // the evolution law's df/dF, df/dz, df/dq are all checked there.
  for (const std::vector<double>& q : {std::vector<double>{4e4, 0.05}, {1e3, 3.0}}) {
    auto m = create_builtin_material("maxwell");
    const auto checks = check_material_derivatives(*m, q);
    int evolution = 0;
    for (const auto& c : checks) {
      EXPECT_TRUE(c.passed()) << c.what << " at " << c.state << " relative error " << c.error;
      evolution += c.what == "df/dF" || c.what == "df/dz" || c.what == "df/dq" ||
                   c.what == "dP/dz" || c.what == "f = 0 when relaxed";
    }
    EXPECT_EQ(evolution, 5 * 8);  // five checks at each of the eight test states
  }
}

namespace {
/// The built-in branch with ∂f/∂z off by 0.1 %: a derivative the check must catch.
class SkewedEvolution final : public Material {
 public:
  std::string name() const override { return "skewed"; }
  const std::vector<ParamInfo>& params() const override { return inner_->params(); }
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  int internal_size() const override { return inner_->internal_size(); }
  void relaxed_internal(const Mat3& F, const double* q, double* z) const override {
    inner_->relaxed_internal(F, q, z);
  }
  void evolve(const MaterialPoint& in, unsigned request, InternalResponse& out) const override {
    inner_->evolve(in, request, out);
    if (request & kTangent) out.dz *= 1.001;
  }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override {
    return inner_->evaluate(in, request, out);
  }

 private:
  std::unique_ptr<Material> inner_ = create_builtin_material("maxwell");
};
}  // namespace

TEST(MaterialLibrary, TheCheckCatchesAWrongEvolutionDerivative) {
  const auto checks = check_material_derivatives(SkewedEvolution(), {4e4, 0.05});
  for (const auto& c : checks)
    EXPECT_EQ(c.passed(), c.what != "df/dz") << c.what << " at " << c.state << " " << c.error;
}

TEST(MaterialLibrary, ObjectivityOfElasticModels) {
  std::mt19937_64 rng(13);
  for (const char* name : kElastic) {
    auto m = create_builtin_material(name);
    const auto q = test_parameters(*m);
    for (int trial = 0; trial < 4; ++trial) {
      const Mat3 F = Mat3::Identity() + random_matrix(rng, 0.3);
      const Mat3 R = rotation(rng);
      const auto r = eval(*m, F, q, kStress | kEnergy);
      const auto rr = eval(*m, R * F, q, kStress | kEnergy);
      EXPECT_LT(rel(rr.P, R * r.P), 1e-10) << name;
      EXPECT_NEAR(rr.energy, r.energy, 1e-10 * std::max(1.0, std::abs(r.energy))) << name;
    }
  }
}

TEST(MaterialLibrary, SplineInitialisedToNeoHookeanReproducesIt) {
  const double lambda = 2e4, mu = 8e3;
  auto nh = create_builtin_material("neo-hookean");
  auto sp = create_builtin_material("spline");
  const auto q = SplineMaterial::neo_hookean_values(lambda, mu);
  std::mt19937_64 rng(17);
  // Anywhere inside the knot ranges (σ in [0.3, 3], J in [0.2, 3]), not just near I.
  std::uniform_real_distribution<double> u(0.3, 3.0);
  int tested = 0;
  while (tested < 50) {
    const Eigen::Vector3d s(u(rng), u(rng), u(rng));
    if (s.prod() < 0.2 || s.prod() > 3.0) continue;
    ++tested;
    const Mat3 F = rotation(rng) * s.asDiagonal() * rotation(rng);
    const auto ref = eval(*nh, F, {lambda, mu}, kStress | kEnergy);
    const auto r = eval(*sp, F, q, kStress | kEnergy);
    EXPECT_LT(rel(r.P, ref.P), 1e-3) << F;
    EXPECT_NEAR(r.energy, ref.energy, 1e-3 * std::abs(ref.energy));
  }
  // Exact at the knots (σ and J both knots).
  const Mat3 F = Eigen::Vector3d(1.2, 1.0, 1.0).asDiagonal();
  EXPECT_LT(rel(eval(*sp, F, q).P, eval(*nh, F, {lambda, mu}).P), 1e-12);
}

TEST(MaterialLibrary, SplineRefusesInvertedElements) {
  auto m = create_builtin_material("spline");
  const auto q = defaults(*m);
  MaterialPoint p;
  p.F = Eigen::Vector3d(-0.5, 1, 1).asDiagonal();
  p.q = q.data();
  MaterialResponse r;
  EXPECT_FALSE(m->evaluate(p, kStress, r));
}

TEST(MaterialLibrary, FiberReducesToNeoHookean) {
  auto nh = create_builtin_material("neo-hookean");
  auto fb = create_builtin_material("fiber");
  std::mt19937_64 rng(19);
  const double a[] = {0, 0.6, 0.8};
  for (int trial = 0; trial < 5; ++trial) {
    const Mat3 F = Mat3::Identity() + random_matrix(rng, 0.3);
    const unsigned req = kStress | kTangent | kEnergy;
    const auto ref = eval(*nh, F, {2e4, 1e4}, req);
    // k1 = 0: no fibre contribution at all.
    const auto r0 = eval(*fb, F, {2e4, 1e4, 0, 1.0}, req, Mat3::Zero(), a);
    EXPECT_LT(rel(r0.P, ref.P), 1e-14);
    EXPECT_LT((r0.dPdF - ref.dPdF).norm(), 1e-14 * ref.dPdF.norm());
    EXPECT_NEAR(r0.energy, ref.energy, 1e-14 * std::abs(ref.energy));
  }
  // Compression along a (and anything else that shortens the fibre): exactly NH.
  const Mat3 Fc = Eigen::Vector3d(0.8, 1.1, 1.1).asDiagonal();
  const auto ref = eval(*nh, Fc, {2e4, 1e4}, kStress | kTangent | kEnergy);
  const auto rc = eval(*fb, Fc, {2e4, 1e4, 5e4, 2.0}, kStress | kTangent | kEnergy);
  EXPECT_EQ(rc.P, ref.P);
  EXPECT_EQ(rc.dPdF, ref.dPdF);
  EXPECT_EQ(rc.energy, ref.energy);
  // Stretch along a stiffens it.
  const Mat3 Ft = Eigen::Vector3d(1.2, 0.95, 0.95).asDiagonal();
  EXPECT_GT(eval(*fb, Ft, {2e4, 1e4, 5e4, 2.0}).P(0, 0), eval(*nh, Ft, {2e4, 1e4}).P(0, 0));
}

TEST(MaterialLibrary, StrainDampingReducesToNewtonian) {
  auto nw = create_builtin_material("newtonian");
  auto sd = create_builtin_material("strain-damping");
  std::mt19937_64 rng(23);
  const unsigned req = kStress | kTangent | kRateTangent;
  for (int trial = 0; trial < 5; ++trial) {
    const Mat3 F = Mat3::Identity() + random_matrix(rng, 0.3);
    const Mat3 Fdot = random_matrix(rng, 1.0);
    const auto ref = eval(*nw, F, {2.5}, req, Fdot);
    const auto r = eval(*sd, F, {2.5, 0, 0}, req, Fdot);
    EXPECT_LT(rel(r.P, ref.P), 1e-14);
    EXPECT_LT((r.dPdF - ref.dPdF).norm(), 1e-14 * ref.dPdF.norm());
    EXPECT_LT((r.dPdFdot - ref.dPdFdot).norm(), 1e-14 * ref.dPdFdot.norm());
    // Stretching raises the viscosity by d1 (σ_max − 1).
    const double smax = Eigen::JacobiSVD<Mat3>(F).singularValues()[0];
    EXPECT_LT(rel(eval(*sd, F, {2.5, 4.0, 0}, kStress, Fdot).P, (1 + 1.6 * (smax - 1)) * ref.P),
              1e-12);
  }
}
