// The nested extensions of the gap diagnosis: extra material terms (lists of
// elastic and viscous terms: stiffening, a fibre, drag, a flow index), multiplier
// fields (elastic.moduli, a Legendre density field) and observation parameters
// (clock offset, marker offsets, registration). At its nominal value each one
// reproduces the nominal model; away from it its gradient agrees three ways; from
// the nominal value a fit recovers an effect put into the data.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include "adjoint/fit_problem.hpp"
#include "adjoint/uncertainty.hpp"
#include "engine/csv.hpp"
#include "fit/fit_loop.hpp"
#include "gradient_agreement.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

const std::string& kMarkers = test::kShakenBarMarkers;

const std::string kNominal = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })";

std::string bar(const std::string& material, const std::string& tail, double end = 0.1) {
  test::ShakenBar b;
  b.material = material.substr(1);
  b.end = end;
  b.rtol = 1e-9;
  b.atol = 1e-13;
  b.tail = tail;
  return test::shaken_bar_yaml(b);
}

/// A scenario of the bar with `material`, observing `tracks` (and `fit`).
Scenario observing(const fs::path& dir, const std::string& name, const std::string& material,
                   const std::string& tracks, const std::string& fit = "", double end = 0.1) {
  test::write_text(dir / (name + ".yaml"),
                   bar(material, kMarkers + "\n  observed: " + tracks + "\n" + fit, end));
  return load_scenario((dir / (name + ".yaml")).string());
}

/// elastic.moduli on the clamped half of the bar (a box), the rest left nominal.
FitParameterSpec moduli_of_the_clamped_half() {
  FitParameterSpec moduli = positive_fit_parameter(kElasticModuli);
  moduli.scope = FitParameterSpec::Scope::Boxes;
  moduli.boxes = {{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.03, 0.02, 0.02)}};
  return moduli;
}

Evaluation phi(FitProblem& problem, const Eigen::VectorXd& p) {
  GradientOptions o;
  o.method = GradientMethod::kNone;
  return problem.evaluate(p, o);
}

}  // namespace

TEST(Extensions, TermListsNameTheirParameters) {
  const fs::path dir = test::scratch("extensions-names");
  const std::string material = R"(
  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: stiffening, c2: 0 }
    - { model: neo-hookean, lambda: 1.0e4, mu: 1.0e4 }
  viscous:
    - { model: newtonian, nu: 20 }
    - { model: drag, c: 0 })";
  test::write_text(dir / "s.yaml", bar(material, kMarkers));
  const Scenario s = load_scenario((dir / "s.yaml").string());
  ASSERT_EQ(s.material.elastic.size(), 3u);
  ASSERT_EQ(s.material.viscous.size(), 2u);
  const auto q = material_quantities(s.material);
  // A parameter that one term of its kind has keeps its short name; shared ones
  // (two neo-Hookean terms) are named by index only.
  ASSERT_NE(find_quantity(q, "elastic.c2"), nullptr);
  EXPECT_EQ(find_quantity(q, "elastic.c2"), find_quantity(q, "elastic[1].c2"));
  EXPECT_EQ(find_quantity(q, "elastic.c2")->term, 1);
  EXPECT_EQ(find_quantity(q, "elastic.mu"), nullptr);
  ASSERT_NE(find_quantity(q, "elastic[2].mu"), nullptr);
  EXPECT_EQ(find_quantity(q, "elastic[2].mu")->term, 2);
  EXPECT_DOUBLE_EQ(find_quantity(q, "elastic[2].mu")->value, 1e4);
  // Viscous terms follow the elastic ones in the model.
  EXPECT_EQ(find_quantity(q, "viscous.c")->term, 4);
  EXPECT_EQ(find_quantity(q, "viscous.nu")->term, 3);
}

TEST(Extensions, EveryExtensionAtItsNominalValueReproducesTheNominalModel) {
  const fs::path dir = test::scratch("extensions-nominal");
  test::write_text(dir / "truth.yaml", bar(R"(
  density: 1000
  elastic: { model: neo-hookean, lambda: 2.4e5, mu: 0.9e5 }
  viscous: { model: newtonian, nu: 25 })",
                                           kMarkers));
  const std::string tracks =
      test::simulate_tracks(dir, "truth", test::read_text(dir / "truth.yaml"));
  // Every map below leaves the nominal values bit for bit (multipliers e⁰ = 1,
  // observations 0): a value block would write exp(ln q), an ulp off, and an
  // adaptive integrator turns an ulp into a trajectory different within its tolerance.
  FitParameterSpec density = linear_fit_parameter("density", -5, 5);
  density.scope = FitParameterSpec::Scope::Legendre;
  density.legendre_axis = 0;
  density.legendre_degree = 2;
  density.initial = 0.0;
  const Scenario nominal = observing(dir, "nominal", kNominal, tracks);
  FitProblem plain(nominal, {density});
  const Evaluation reference = phi(plain, plain.map().initial());
  ASSERT_TRUE(reference.ok) << reference.error;
  ASSERT_GT(reference.phi, 0);

  const std::string extended = R"(
  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: stiffening, c2: 0 }
    - { model: fibre, k: 0, theta: 0.7, phi: 1.2 }
  viscous:
    - { model: power-law, nu: 20, h: 1 }
    - { model: drag, c: 0 })";
  const Scenario s = observing(dir, "extended", extended, tracks);
  FitParameterSpec moduli = moduli_of_the_clamped_half();
  FitProblem problem(s, {moduli, density, linear_fit_parameter(kClockOffset, -0.05, 0.05),
                         linear_fit_parameter("markers.tip.offset", -0.01, 0.01),
                         linear_fit_parameter(kRegistration, -0.1, 0.1)});
  EXPECT_EQ(problem.map().size(), 2 + 3 + 1 + 3 + 6);
  const Evaluation e = phi(problem, problem.map().initial());
  ASSERT_TRUE(e.ok) << e.error;
  EXPECT_EQ(e.experiments[0].forward_stats.steps, reference.experiments[0].forward_stats.steps);
  EXPECT_EQ(e.phi, reference.phi);
}

TEST(Extensions, GradientsOfEveryExtensionAgreeThreeWays) {
  const fs::path dir = test::scratch("extensions-gradient");
  const std::string tracks = test::simulate_tracks(dir, "truth", bar(kNominal, kMarkers));
  const std::string material = R"(
  density: 1000
  elastic:
    - { model: neo-hookean, lambda: 2.2e5, mu: 0.9e5 }
    - { model: stiffening, c2: 2.0e4 }
    - { model: fibre, k: 3.0e4, theta: 0.5, phi: 1.0 }
  viscous:
    - { model: power-law, nu: 25, h: 0.9 }
    - { model: drag, c: 1.5 })";
  const Scenario s = observing(dir, "fit", material, tracks);
  FitParameterSpec moduli = moduli_of_the_clamped_half();
  moduli.initial = 1.1;
  FitParameterSpec density = linear_fit_parameter("density", -5, 5);
  density.scope = FitParameterSpec::Scope::Legendre;
  density.legendre_axis = 0;
  density.legendre_degree = 1;
  density.initial = 0.1;
  FitParameterSpec clock = linear_fit_parameter(kClockOffset, -0.05, 0.05);
  clock.initial = 0.004;
  FitParameterSpec offset = linear_fit_parameter("markers.tip.offset", -0.01, 0.01);
  offset.initial = 0.001;
  FitParameterSpec registration = linear_fit_parameter(kRegistration, -0.1, 0.1);
  registration.initial = 0.01;
  FitProblem problem(
      s, {positive_fit_parameter("elastic.c2"), positive_fit_parameter("elastic.k"),
          linear_fit_parameter("elastic.theta", -4, 4), positive_fit_parameter("viscous.h"),
          positive_fit_parameter("viscous.c"), moduli, density, clock, offset, registration});
  test::expect_gradients_agree(problem);
}

// Data made with the effect on, fitted from the nominal value: the effect comes back.
struct Recovery {
  std::string name, truth_material, fit_material;
  FitParameterSpec parameter;
  double truth;
  double tolerance;               // relative, noise-free data
  std::string truth_observation;  // applied to the truth's tracks (see below)
  friend void PrintTo(const Recovery& r, std::ostream* os) { *os << r.name; }
};

class ExtensionRecovery : public ::testing::TestWithParam<Recovery> {};

TEST_P(ExtensionRecovery, TheFitFindsTheEffectFromItsNominalValue) {
  const Recovery& c = GetParam();
  const fs::path dir = test::scratch("extensions-recovery-" + c.name);
  std::string tracks = test::simulate_tracks(dir, "truth", bar(c.truth_material, kMarkers, 0.15));
  if (!c.truth_observation.empty()) {
    // An observation effect acts on the capture, not the body: shift the tracks.
    MarkerTracks t = read_marker_tracks(tracks);
    // Recorded late by τ: the capture's clock reads t + τ at model time t.
    if (c.truth_observation == "late")
      for (double& time : t.times) time += c.truth;
    tracks = test::write_marker_tracks(t, dir / "shifted.csv");
  }
  const Scenario s = observing(dir, "fit", c.fit_material, tracks, "", 0.15);
  FitProblem problem(s, {c.parameter});
  FitOptions o;
  o.max_evaluations = 40;
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  ASSERT_GT(out.evaluations, 0);
  const double fitted = problem.map().value(out.p, 0);
  EXPECT_NEAR(fitted, c.truth, c.tolerance * std::abs(c.truth))
      << c.name << ": " << out.stop_reason << " after " << out.evaluations << " evaluations";
}

const std::string kWithStiffening = R"(
  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: stiffening, c2: 3.0e5 }
  viscous: { model: newtonian, nu: 20 })";
const std::string kNominalWithStiffening = R"(
  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: stiffening, c2: 0 }
  viscous: { model: newtonian, nu: 20 })";
const std::string kWithDrag = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous:
    - { model: newtonian, nu: 20 }
    - { model: drag, c: 40 })";
const std::string kNominalWithDrag = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous:
    - { model: newtonian, nu: 20 }
    - { model: drag, c: 0 })";
const std::string kWithFibre = R"(
  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: fibre, k: 1.0e5, theta: 0.7853981633974483, phi: 1.5707963267948966 }
  viscous: { model: newtonian, nu: 20 })";
const std::string kNominalWithFibre = R"(
  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: fibre, k: 0, theta: 0.7853981633974483, phi: 1.5707963267948966 }
  viscous: { model: newtonian, nu: 20 })";

INSTANTIATE_TEST_SUITE_P(
    Nested, ExtensionRecovery,
    ::testing::Values(Recovery{"stiffening", kWithStiffening, kNominalWithStiffening,
                               linear_fit_parameter("elastic.c2", 0, 1e7), 3e5, 0.02, ""},
                      Recovery{"drag", kWithDrag, kNominalWithDrag,
                               linear_fit_parameter("viscous.c", 0, 1e4), 40, 0.02, ""},
                      Recovery{"fibre", kWithFibre, kNominalWithFibre,
                               linear_fit_parameter("elastic.k", 0, 1e7), 1e5, 0.02, ""},
                      Recovery{"clock", kNominal, kNominal,
                               linear_fit_parameter(kClockOffset, -0.05, 0.05), 0.01, 0.02,
                               "late"}),
    [](const auto& info) { return info.param.name; });

// The screening scores a fibre from its sensitivities at the nested k = 0, where the
// term has no stress but a derivative: adjoint, forward sensitivities and central
// differences agree there too (with the modulus beside it, and alone).
TEST(Extensions, AFibreAtZeroStiffnessHasItsGradientAgreeThreeWays) {
  const fs::path dir = test::scratch("extensions-fibre-at-zero");
  const std::string tracks = test::simulate_tracks(dir, "truth", bar(kWithFibre, kMarkers));
  const Scenario s = observing(dir, "fit", kNominalWithFibre, tracks);
  FitProblem both(
      s, {linear_fit_parameter("elastic.k", -1e7, 1e7), positive_fit_parameter("elastic.mu")});
  test::expect_gradients_agree(both);
  FitProblem alone(s, {linear_fit_parameter("elastic.k", -1e7, 1e7)});
  test::expect_gradients_agree(alone);
}

// A fibre fitted from its nested k = 0 with its direction free: there the angles move
// no marker, so JᵀJ is singular in them. The Gauss–Newton scaling of the start holds
// them (zero rows of root_inverse) and scales the rest, instead of refusing and
// leaving L-BFGS unscaled (V10's anisotropy refit then tried a point 8× off in rms);
// once k is off zero a restart frees them, and stiffness and direction come back.
TEST(Extensions, AFibreAndItsDirectionAreRecoveredFromZeroStiffness) {
  const fs::path dir = test::scratch("extensions-fibre-direction");
  const std::string tracks = test::simulate_tracks(dir, "truth", bar(kWithFibre, kMarkers, 0.15));
  const std::string nominal = R"(
  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: fibre, k: 0, theta: 0.6, phi: 1.4 }
  viscous: { model: newtonian, nu: 20 })";
  const Scenario s = observing(dir, "fit", nominal, tracks, "", 0.15);
  FitProblem problem(
      s, {linear_fit_parameter("elastic.k", 0, 1e7), linear_fit_parameter("elastic.theta", -4, 4),
          linear_fit_parameter("elastic.phi", -4, 4)});
  const ParameterUncertainty u = gauss_newton_uncertainty(problem, problem.map().initial());
  ASSERT_EQ(u.root_inverse.rows(), 3);
  EXPECT_GT(u.root_inverse.row(0).norm(), 0);
  EXPECT_EQ(u.root_inverse.row(1).norm(), 0);
  EXPECT_EQ(u.root_inverse.row(2).norm(), 0);
  EXPECT_FALSE(u.ok);
  EXPECT_NE(u.error.find("theta does not move any observed marker"), std::string::npos) << u.error;

  FitOptions o;
  o.max_evaluations = 60;
  o.gauss_newton_start = true;
  std::string lines;
  o.on_progress = [&](const std::string& line) { lines += line + "\n"; };
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  EXPECT_NE(lines.find("the start point is evaluated: going on in Gauss–Newton-scaled"),
            std::string::npos)
      << lines;
  const double k = problem.map().value(out.p, 0), theta = problem.map().value(out.p, 1),
               phi = problem.map().value(out.p, 2);
  EXPECT_NEAR(k, 1e5, 0.02e5) << out.stop_reason << " after " << out.evaluations;
  // The fibre's axis, not its sign: a and −a are the same fibre.
  const Eigen::Vector3d a(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                          std::cos(theta));
  EXPECT_GT(std::abs(a.dot(Eigen::Vector3d(0, 1, 1).normalized())), std::cos(0.02))
      << "theta " << theta << " phi " << phi;
}

/// The truth's tracks as a capture whose clock runs late by `lag`, with N(0, σ²) on every
/// coordinate and a burst of occluded frames per marker (frames [first + 7 m, +5)).
std::string late_noisy_occluded(const std::string& file, const fs::path& out, double lag,
                                double sigma, int first) {
  MarkerTracks t = read_marker_tracks(file);
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, sigma);
  std::string csv = "t";
  for (const auto& n : t.names) csv += "," + n + "_x," + n + "_y," + n + "_z";
  csv += "\n";
  for (long k = 0; k < t.xyz.cols(); ++k) {
    csv += fmt::format("{:.12g}", t.times[k] + lag);
    for (long r = 0; r < t.xyz.rows(); ++r) {
      const long m = r / 3, burst = first + 7 * m;
      csv += k >= burst && k < burst + 5 ? std::string(",")
                                         : fmt::format(",{:.12g}", t.xyz(r, k) + noise(rng));
    }
    csv += "\n";
  }
  test::write_text(out, csv);
  return out.string();
}

// A late capture clock with noise and occlusions: where the shifted clock reads past
// the end of a run of seen frames, the residual fades out within a frame interval
// instead of comparing with the run's end cubic extrapolated through noise. The lag
// (2.4 frames) comes back, and the gradient at a lag that reads past every burst's
// edges agrees three ways.
TEST(Extensions, AClockOffsetIsRecoveredFromNoisyOccludedTracks) {
  const fs::path dir = test::scratch("extensions-clock-occluded");
  constexpr double kLag = 0.018, kSigma = 1e-4;
  test::ShakenBar b;
  b.material = kNominal.substr(1);
  b.frequency_y = 8;
  b.frequency_z = 6;
  b.end = 0.15;
  b.tail = kMarkers;
  const std::string truth = test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(b));
  b.tail += "\n  observed: " +
            late_noisy_occluded(truth, dir / "captured.csv", kLag, kSigma, /*first=*/6) + "\n";
  test::write_text(dir / "fit.yaml", test::shaken_bar_yaml(b));
  const Scenario s = load_scenario((dir / "fit.yaml").string());

  FitParameterSpec clock = linear_fit_parameter(kClockOffset, -0.05, 0.05);
  clock.initial = 0.0093;  // between frames, past the bursts' edges by under a frame
  FitProblem at_lag(s, {positive_fit_parameter("viscous.nu"), clock});
  test::expect_gradients_agree(at_lag);

  FitProblem problem(s, {linear_fit_parameter(kClockOffset, -0.05, 0.05)});
  FitOptions o;
  o.max_evaluations = 40;
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  ASSERT_GT(out.evaluations, 0);
  // Noise of σ on ~300 coordinates against tracks moving ~0.1 m/s: ≈ 0.1 ms.
  EXPECT_NEAR(problem.map().value(out.p, 0), kLag, 5e-4)
      << out.stop_reason << " after " << out.evaluations << " evaluations";
  // Each captured frame is compared with the model at t − τ, so that at the fitted
  // lag the frame residual is the capture's noise, σ per coordinate (~300: ±4 %).
  const GaussNewtonSystem at_fit = gauss_newton_system(problem, out.p, nullptr, false);
  ASSERT_TRUE(at_fit.ok) << at_fit.error;
  const double rms =
      at_fit.residual.norm() / std::sqrt(static_cast<double>(at_fit.residual.size()));
  EXPECT_NEAR(rms, kSigma, 0.15 * kSigma);
}

// A marker glued off its nominal place: the truth's marker sits at X + δ inside the
// tet that holds the nominal X (its centroid), where the linear field's position is
// x(X) + F δ, exactly what the offset parameter adds; the fit recovers δ.
TEST(Extensions, AMarkerOffsetIsRecoveredFromTheNominalPlace) {
  const fs::path dir = test::scratch("extensions-recovery-offset");
  test::write_text(dir / "mesh.yaml", bar(kNominal, "", 0.15));
  const Mesh mesh = load_scenario((dir / "mesh.yaml").string()).mesh;
  // The tet nearest the free end's centre line, and the radius of its inscribed sphere.
  int best = 0;
  double nearest = HUGE_VAL;
  for (int e = 0; e < mesh.num_tets(); ++e) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) c += mesh.nodes.col(mesh.tets(a, e)) / 4;
    if (const double d = (c - Eigen::Vector3d(0.055, 0.01, 0.01)).norm(); d < nearest) {
      nearest = d;
      best = e;
    }
  }
  Eigen::Matrix3Xd v(3, 4);
  for (int a = 0; a < 4; ++a) v.col(a) = mesh.nodes.col(mesh.tets(a, best));
  const Eigen::Vector3d centre = v.rowwise().mean();
  double area = 0;
  for (int a = 0; a < 4; ++a) {
    const Eigen::Vector3d p = v.col((a + 1) % 4), q = v.col((a + 2) % 4), r = v.col((a + 3) % 4);
    area += 0.5 * (q - p).cross(r - p).norm();
  }
  const double volume =
      std::abs((v.col(1) - v.col(0)).dot((v.col(2) - v.col(0)).cross(v.col(3) - v.col(0)))) / 6;
  const Eigen::Vector3d delta(0.2 * 3 * volume / area, -0.3 * 3 * volume / area, 0);
  const auto markers = [](const Eigen::Vector3d& at) {
    return fmt::format(R"(
markers:
  rest:
    - {{ name: tip, at: [{:.17g}, {:.17g}, {:.17g}] }}
    - {{ name: mid, at: [0.03, 0.01, 0.02] }})",
                       at.x(), at.y(), at.z());
  };
  const std::string tracks =
      test::simulate_tracks(dir, "truth", bar(kNominal, markers(centre + delta), 0.15));
  test::write_text(dir / "fit.yaml",
                   bar(kNominal, markers(centre) + "\n  observed: " + tracks + "\n", 0.15));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(s, {linear_fit_parameter("markers.tip.offset", -0.01, 0.01)});
  FitOptions o;
  o.max_evaluations = 40;
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  ASSERT_GT(out.evaluations, 0);
  for (int k = 0; k < 3; ++k)
    EXPECT_NEAR(out.p[k], delta[k], 0.02 * delta.norm())
        << "axis " << k << ": " << out.stop_reason << " after " << out.evaluations
        << " evaluations";
}

}  // namespace kelvin
