// Simulated marker trajectories and their sensitivities, and Gauss–Newton parameter
// uncertainties. The truth is simulated once by kelvin's normal path (markers.csv);
// the other tests compare against it or perturb it with known noise.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include "adjoint/fit_problem.hpp"
#include "adjoint/marker_trajectory.hpp"
#include "adjoint/uncertainty.hpp"
#include "base/error.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

/// The shaken bar of test_support.hpp with five markers sampled at 1 kHz: enough
/// coordinates (~10³) that σ̂ is within a few per cent of σ for any noise draw.
std::string bar_yaml(const std::string& material, const std::string& observed) {
  test::ShakenBar bar;
  bar.material = material.substr(1);  // the constants below start with a newline
  bar.output_rate = 1000;
  bar.tail = R"(markers:
  rest:
    - { name: tip, at: [0.06, 0.01, 0.01] }
    - { name: mid, at: [0.03, 0.01, 0.02] }
    - { name: corner, at: [0.05, 0.0, 0.0] }
    - { name: side, at: [0.045, 0.02, 0.01] }
    - { name: root, at: [0.005, 0.01, 0.01] }
)" + observed;
  return test::shaken_bar_yaml(bar);
}

const std::string kTruth = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: power-law, nu: 20, h: 0.8 })";
const std::string kStart = R"(
  density: 1300
  elastic: { model: neo-hookean, lambda: 2.6e5, mu: 0.8e5 }
  viscous: { model: power-law, nu: 30, h: 0.9 })";

std::vector<FitParameterSpec> params(const std::vector<std::string>& targets) {
  std::vector<FitParameterSpec> out;
  for (const auto& t : targets) out.push_back(positive_fit_parameter(t));
  return out;
}

class MarkerTrajectoryTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / "kelvin-marker-trajectory";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    std::ofstream(dir_ / "truth.yaml") << bar_yaml(kTruth, "");
    SimulationOptions o;
    o.outdir = (dir_ / "truth").string();
    const SimulationResult r = run_simulation(load_scenario((dir_ / "truth.yaml").string()), o);
    ASSERT_TRUE(r.completed) << r.error;
  }

  /// A scenario with `material` whose observed tracks are the truth's markers.csv.
  static Scenario scenario(const std::string& material, const std::string& name) {
    const fs::path path = dir_ / (name + ".yaml");
    std::ofstream(path) << bar_yaml(
        material, "  observed: " + (dir_ / "truth" / "markers.csv").string() + "\n");
    return load_scenario(path.string());
  }

  static fs::path dir_;
};

fs::path MarkerTrajectoryTest::dir_;

TEST_F(MarkerTrajectoryTest, PositionsMatchTheSimulationsMarkerCsv) {
  const Scenario s = scenario(kTruth, "positions");
  FitProblem problem(s, params({"elastic.mu", "viscous.nu"}));
  const MarkerTracks& truth = s.markers.observed;
  ASSERT_EQ(truth.times.size(), 101u);
  ASSERT_EQ(truth.names.size(), s.markers.embedded.size());
  const Eigen::VectorXd p = problem.map().initial();
  for (const bool sensitivities : {false, true}) {
    const MarkerTrajectory traj = simulate_markers(problem, 0, p, truth.times, sensitivities);
    ASSERT_TRUE(traj.ok) << traj.error;
    ASSERT_EQ(traj.positions.size(), truth.times.size());
    EXPECT_EQ(traj.residual_sensitivities.size(), sensitivities ? truth.times.size() : 0u);
    EXPECT_EQ(traj.residuals.size(), truth.times.size());
    double worst = 0;
    for (size_t k = 0; k < truth.times.size(); ++k) {
      ASSERT_EQ(traj.positions[k].cols(), static_cast<Eigen::Index>(truth.names.size()));
      for (size_t i = 0; i < truth.names.size(); ++i)
        worst = std::max(
            worst, (traj.positions[k].col(i) - truth.xyz.col(k).segment<3>(3 * static_cast<int>(i)))
                       .cwiseAbs()
                       .maxCoeff());
    }
    // markers.csv has 9 significant digits (~1e-10 m); the runs take different steps
    // (Φ's quadrature is under error control here), so they agree to the tolerance.
    EXPECT_LT(worst, 1e-9) << "with sensitivities: " << sensitivities;
    std::printf("positions vs markers.csv (sensitivities %d): max |Δ| = %.3g m\n", sensitivities,
                worst);
  }
}

TEST_F(MarkerTrajectoryTest, SensitivitiesMatchCentralDifferences) {
  const Scenario s = scenario(kStart, "sensitivities");
  FitProblem problem(s, params({"elastic.mu", "viscous.nu", "density"}));
  const ParameterMap& map = problem.map();
  const Eigen::VectorXd p = map.initial();
  // t = 0 is the static state (x₀_p = −K₀⁻¹ ∂R/∂p); the others lie between steps.
  const std::vector<double> times{0.0, 0.0137, 0.0371, 0.06};
  const MarkerTrajectory traj = simulate_markers(problem, 0, p, times, true);
  ASSERT_TRUE(traj.ok) << traj.error;
  // Every marker is observed, in the embedding's order: residual rows are marker rows.
  ASSERT_EQ(problem.experiment(0).objective().names().size(), s.markers.embedded.size());
  for (size_t i = 0; i < s.markers.embedded.size(); ++i)
    ASSERT_EQ(problem.experiment(0).objective().names()[i], s.markers.embedded[i].name);
  // Positions differ from run to run by ~4e-11 m (adaptive steps at rtol 1e-9), which
  // a plain central difference divides by δ: for ν (|dx*/dp| ~ 1 mm) that is 4e-4 at
  // δ = 1e-4. Richardson-extrapolated differences are O(δ⁴) and allow δ = 0.02.
  const double delta = 0.02;  // in ln q
  for (int j = 0; j < map.size(); ++j) {
    auto central = [&](double h) {
      Eigen::VectorXd pp = p, pm = p;
      pp[j] += h;
      pm[j] -= h;
      const MarkerTrajectory plus = simulate_markers(problem, 0, pp, times, false);
      const MarkerTrajectory minus = simulate_markers(problem, 0, pm, times, false);
      EXPECT_TRUE(plus.ok && minus.ok) << plus.error << minus.error;
      std::vector<Eigen::Matrix3Xd> d;
      for (size_t k = 0; k < times.size(); ++k)
        d.push_back((plus.positions[k] - minus.positions[k]) / (2 * h));
      return d;
    };
    const auto d1 = central(delta), d2 = central(2 * delta);
    double error = 0, norm = 0;
    for (size_t k = 0; k < times.size(); ++k) {
      const Eigen::Matrix3Xd fd = (4 * d1[k] - d2[k]) / 3;
      const Eigen::VectorXd exact = traj.residual_sensitivities[k].col(j);
      error += (Eigen::Map<const Eigen::VectorXd>(fd.data(), fd.size()) - exact).squaredNorm();
      norm += exact.squaredNorm();
    }
    const double rel = std::sqrt(error / norm);
    std::printf("%s: |dx*/dp| = %.3g m, relative FD difference %.3g\n", map.label(j).c_str(),
                std::sqrt(norm), rel);
    EXPECT_LT(rel, 1e-5) << map.label(j);
    EXPECT_GT(norm, 1e-10) << map.label(j);  // the markers do move with p_j
  }
}

// The observation entries' columns of dr/dp (clock offset, a marker's rest offset,
// the capture's registration) against central differences of the residuals, at a
// point off the nominal so that every term of the derivative is exercised.
TEST_F(MarkerTrajectoryTest, ObservationColumnsMatchCentralDifferences) {
  const Scenario s = scenario(kStart, "observation-columns");
  std::vector<FitParameterSpec> specs = params({"elastic.mu"});
  for (const char* target : {kClockOffset, "markers.tip.offset", kRegistration})
    specs.push_back(linear_fit_parameter(target, -0.1, 0.1));
  FitProblem problem(s, specs);
  const ParameterMap& map = problem.map();
  ASSERT_EQ(map.size(), 1 + 1 + 3 + 6);
  Eigen::VectorXd p = map.initial();
  p.tail(10) << 0.004, 1e-3, -2e-3, 5e-4, 0.02, -0.01, 0.03, 1e-3, 2e-3, -1e-3;
  const std::vector<double> times{0.0137, 0.0371, 0.06};
  const MarkerTrajectory traj = simulate_markers(problem, 0, p, times, true);
  ASSERT_TRUE(traj.ok) << traj.error;
  for (int j = 1; j < map.size(); ++j) {
    // The clock's step is set by the tracks' curvature, the others by round-off.
    const double h = j == 1 ? 1e-6 : 1e-4;
    Eigen::VectorXd pp = p, pm = p;
    pp[j] += h;
    pm[j] -= h;
    const MarkerTrajectory plus = simulate_markers(problem, 0, pp, times, true);
    const MarkerTrajectory minus = simulate_markers(problem, 0, pm, times, true);
    ASSERT_TRUE(plus.ok && minus.ok);
    double error = 0, norm = 0;
    for (size_t k = 0; k < times.size(); ++k) {
      const Eigen::Matrix3Xd fd = (plus.residuals[k] - minus.residuals[k]) / (2 * h);
      const Eigen::VectorXd exact = traj.residual_sensitivities[k].col(j);
      error += (Eigen::Map<const Eigen::VectorXd>(fd.data(), fd.size()) - exact).squaredNorm();
      norm += exact.squaredNorm();
    }
    const double rel = std::sqrt(error / norm);
    std::printf("%s: |dr/dp| = %.3g, relative FD difference %.3g\n", map.label(j).c_str(),
                std::sqrt(norm), rel);
    EXPECT_LT(rel, 1e-5) << map.label(j);
    EXPECT_GT(norm, 1e-6) << map.label(j);
  }
}

// A clock offset compares each captured frame with the model at t − τ, never the
// capture between its frames: a cubic spline through white noise, read half a frame
// off, keeps only about 75 % of its variance, so reading the capture there would
// credit any offset with a quarter of the noise as a misfit drop (on V04 of the
// diagnosis cases a 1.9 ms lag beat the true drag model that way). With the true
// model and noisy tracks, half a frame's offset must not lower the frame residual.
TEST_F(MarkerTrajectoryTest, AClockOffsetDoesNotAverageTheCapturesNoise) {
  Scenario s = scenario(kTruth, "clock-noise");
  MarkerTracks& tracks = s.markers.observed;
  std::mt19937 rng(20261208);
  std::normal_distribution<double> normal(0, 1e-3);
  for (Eigen::Index k = 0; k < tracks.xyz.cols(); ++k)
    for (Eigen::Index r = 0; r < tracks.xyz.rows(); ++r) tracks.xyz(r, k) += normal(rng);
  std::vector<FitParameterSpec> specs = params({"elastic.mu"});
  specs.push_back(linear_fit_parameter(kClockOffset, -0.1, 0.1));
  FitProblem problem(s, specs);
  const double frame = tracks.times[1] - tracks.times[0];
  const auto sum_sq = [&](double tau) {
    Eigen::VectorXd p = problem.map().initial();
    p[1] = tau;
    const MarkerTrajectory traj = simulate_markers(problem, 0, p, tracks.times, false);
    EXPECT_TRUE(traj.ok) << traj.error;
    double sum = 0;
    int n = 0;
    for (const auto& r : traj.residuals)
      for (Eigen::Index j = 0; j < r.size(); ++j)
        if (std::isfinite(r.data()[j])) {
          sum += r.data()[j] * r.data()[j];
          ++n;
        }
    return std::make_pair(sum, n);
  };
  const auto [at_zero, n_zero] = sum_sq(0);
  const auto [half_frame, n_half] = sum_sq(0.5 * frame);
  EXPECT_EQ(n_zero, n_half);  // the same samples at every offset
  // The true model: the residual is the noise, σ² per coordinate.
  EXPECT_NEAR(at_zero / n_zero, 1e-6, 0.1e-6);
  // Half a frame moves the model by v·h/2 (0.16 mm at the clamp's 0.32 m/s): the
  // misfit rises by about 3 %, give or take its cross term with the noise (~1 %);
  // the capture read between frames loses ~20 % (0.81 of it on this draw).
  std::printf("frame residual: %.4g mm² per coordinate at τ = 0, %.4g at half a frame\n",
              1e6 * at_zero / n_zero, 1e6 * half_frame / n_half);
  EXPECT_GT(half_frame, 0.97 * at_zero);
  EXPECT_LT(half_frame, 1.1 * at_zero);
}

TEST_F(MarkerTrajectoryTest, UncertaintyRecoversTheNoiseLevel) {
  // Noise on the truth's tracks; the root marker has weight 0, the tip is hidden in
  // frames 30..49, and the window starts at frame 10.
  Scenario s1 = scenario(kTruth, "noise");
  s1.fit.objective.weights["root"] = 0;
  s1.fit.objective.window_begin = 0.01;
  MarkerTracks& tracks = s1.markers.observed;
  const Eigen::MatrixXd truth = tracks.xyz;
  std::mt19937 rng(20240611);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd noise(truth.rows(), truth.cols());
  for (Eigen::Index k = 0; k < noise.cols(); ++k)
    for (Eigen::Index r = 0; r < noise.rows(); ++r) noise(r, k) = normal(rng);
  const int tip = static_cast<int>(std::find(tracks.names.begin(), tracks.names.end(), "tip") -
                                   tracks.names.begin());
  for (int k = 30; k < 50; ++k) noise.col(k).segment<3>(3 * tip).setConstant(NAN);
  Scenario s2 = s1;
  s1.markers.observed.xyz = truth + 1e-3 * noise;
  // The same draws doubled: σ̂ and the standard errors must double, free of
  // sampling noise in the comparison.
  s2.markers.observed.xyz = truth + 2e-3 * noise;

  const auto targets = params({"elastic.lambda", "elastic.mu", "viscous.nu", "viscous.h"});
  FitProblem one(s1, targets), two(s2, targets);
  const Eigen::VectorXd p = one.map().initial();  // the true parameters
  const ParameterUncertainty a = gauss_newton_uncertainty(one, p);
  ASSERT_TRUE(a.ok) << a.error;
  // Frames 10..100 (91) × 4 weighted markers − 21 tip frames, 3 coordinates each: as
  // in Φ, a frame counts when the interval ending there was seen (frame 50 does not).
  EXPECT_EQ(a.observations, (91 * 4 - 21) * 3);
  EXPECT_NEAR(a.sigma, 1e-3, 0.1e-3);
  ASSERT_EQ(a.covariance.rows(), 4);
  EXPECT_LT((a.covariance - a.covariance.transpose()).norm(), 1e-12 * a.covariance.norm());
  for (int j = 0; j < 4; ++j) {
    EXPECT_GT(a.std_error_p[j], 0);
    EXPECT_NEAR(a.std_error[j], one.map().value(p, j) * a.std_error_p[j], 1e-12 * a.std_error[j]);
    std::printf("%s = %.4g ± %.3g (σ_p %.3g)\n", one.map().label(j).c_str(), one.map().value(p, j),
                a.std_error[j], a.std_error_p[j]);
  }
  std::printf("N = %d, sigma = %.4g mm\n", a.observations, 1e3 * a.sigma);

  const ParameterUncertainty b = gauss_newton_uncertainty(two, p);
  ASSERT_TRUE(b.ok) << b.error;
  EXPECT_EQ(b.observations, a.observations);
  EXPECT_NEAR(b.sigma / a.sigma, 2.0, 0.02);
  for (int j = 0; j < 4; ++j) EXPECT_NEAR(b.std_error[j] / a.std_error[j], 2.0, 0.02);
}

TEST_F(MarkerTrajectoryTest, ScalingInvarianceIsReportedAsUnidentifiable) {
  // Density, stiffness and viscosity scaled together (gravity and inertia with ρ)
  // leave the motion unchanged: ln λ + ln μ + ln ν + ln ρ is unidentifiable.
  const Scenario s = scenario(kTruth, "singular");
  FitProblem problem(s, params({"elastic.lambda", "elastic.mu", "viscous.nu", "density"}));
  const ParameterUncertainty u = gauss_newton_uncertainty(problem, problem.map().initial());
  EXPECT_FALSE(u.ok);
  EXPECT_NE(u.error.find("not identifiable"), std::string::npos) << u.error;
  for (const char* term :
       {"+1·ln elastic.lambda", "+1·ln elastic.mu", "+1·ln viscous.nu", "+1·ln density"})
    EXPECT_NE(u.error.find(term), std::string::npos) << term << " in: " << u.error;
  std::printf("%s\n", u.error.c_str());
}

TEST_F(MarkerTrajectoryTest, JointExperimentWithAnotherMaterialModelIsRefusedUpFront) {
  Scenario s = scenario(kTruth, "joint-main");
  const Scenario other = scenario(R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })",
                                  "joint-newtonian");
  s.fit.experiments = {other.path};
  try {
    FitProblem problem(s, params({"elastic.mu", "viscous.h"}));
    ADD_FAILURE() << "a power-law fit with a Newtonian experiment was accepted";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("joint-newtonian.yaml's viscous material model is 'newtonian'"),
              std::string::npos)
        << m;
    EXPECT_NE(m.find("'power-law'"), std::string::npos) << m;
  }
}

TEST_F(MarkerTrajectoryTest, FailuresAreReportedNotThrown) {
  const Scenario s = scenario(kTruth, "failures");
  FitProblem problem(s, params({"elastic.mu"}));
  const Eigen::VectorXd p = problem.map().initial();
  std::atomic<bool> interrupt{true};
  const MarkerTrajectory stopped = simulate_markers(problem, 0, p, {0.0, 0.05}, true, &interrupt);
  EXPECT_FALSE(stopped.ok);
  EXPECT_NE(stopped.error.find("interrupted at t = 0"), std::string::npos) << stopped.error;
  EXPECT_EQ(stopped.positions.size(), 1u);  // the sample before the interrupt is kept

  const MarkerTrajectory late = simulate_markers(problem, 0, p, {0.05, 0.2}, false);
  EXPECT_FALSE(late.ok);
  EXPECT_NE(late.error.find("t = 0.2"), std::string::npos) << late.error;
}

TEST_F(MarkerTrajectoryTest, PerElementFieldsAreNotComputed) {
  // 1152 tets: the limit is checked before any simulation.
  std::string yaml =
      bar_yaml(kTruth, "  observed: " + (dir_ / "truth" / "markers.csv").string() + "\n");
  yaml.replace(yaml.find("element_size: 0.01"), 18, "element_size: 0.005");
  std::ofstream(dir_ / "fine.yaml") << yaml;
  const Scenario s = load_scenario((dir_ / "fine.yaml").string());
  FitParameterSpec field = positive_fit_parameter("elastic.mu");
  field.scope = FitParameterSpec::Scope::PerElement;
  FitProblem problem(s, {field});
  ASSERT_GT(problem.map().size(), 200);
  const ParameterUncertainty u = gauss_newton_uncertainty(problem, problem.map().initial());
  EXPECT_FALSE(u.ok);
  EXPECT_NE(u.error.find("limit 200"), std::string::npos) << u.error;
}

}  // namespace
}  // namespace kelvin
