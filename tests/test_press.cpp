// Displacement-controlled probing: a probe pressed to a depth holds its nodes there
// (a ramped clamp the static load steps bring in) and its force on the body is the
// held nodes' reaction (engine/clamp_reaction.hpp). Checked against EAδ/L on a column
// without Poisson effect, by the global balance of forces, through a press deep
// enough to invert the start, by central differences of the static term's gradient
// and Gauss–Newton rows, and by what the measured force adds to the inverses: the
// moduli's scale, which markers alone cannot give.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "adjoint/fit_problem.hpp"
#include "base/error.hpp"
#include "engine/clamp_reaction.hpp"
#include "engine/static_solver.hpp"
#include "probing/displacement_inverse.hpp"
#include "probing/force_inverse.hpp"
#include "probing/probe_experiment.hpp"
#include "test_support.hpp"

namespace kelvin {
namespace {

using test::fs::path;

/// A 40 × 40 × 20 mm foam block on a table, pressed at the centre of its top face by
/// a 12 mm square indenter to `depth`, and at the left with a sideways slip.
std::string pressed_block(const std::string& material, const std::string& measurements,
                          const std::string& extra = "") {
  return "name: pressed-block\n"
         "mesh: { generate: box, lo: [0, 0, 0], hi: [0.04, 0.04, 0.02], element_size: 0.005 }\n"
         "material:\n  density: 60\n" +
         material +
         "\ngravity: [0, 0, 0]\n"
         "clamps: [{ name: table, select: { plane: { axis: z, at: 0 } } }]\n"
         "markers:\n  rest:\n"
         "    - { name: a, at: [0.01, 0.01, 0.02] }\n"
         "    - { name: b, at: [0.03, 0.01, 0.02] }\n"
         "    - { name: c, at: [0.01, 0.03, 0.02] }\n"
         "    - { name: d, at: [0.03, 0.03, 0.02] }\n"
         "    - { name: e, at: [0.02, 0.0, 0.01] }\n"
         "    - { name: f, at: [0.0, 0.02, 0.01] }\n"
         "probing:\n" +
         extra + "  measurements:\n" + measurements;
}

const std::string kTruth = "  elastic: { model: neo-hookean, lambda: 2.0e4, mu: 1.0e4 }";
const std::string kStart = "  elastic: { model: neo-hookean, lambda: 8.0e4, mu: 1.5e4 }";

std::string press_entry(const std::string& name, const std::string& box, const Eigen::Vector3d& d,
                        const std::string& tail) {
  return fmt::format(
      "    - name: {}\n      press: [{{ name: tip, select: {{ box: {} }}, displacement: [{}, {}, "
      "{}]{} }}]\n",
      name, box, d.x(), d.y(), d.z(), tail);
}

const std::string kCentre = "{ lo: [0.014, 0.014, 0.0199], hi: [0.026, 0.026, 0.0201] }";
const std::string kLeft = "{ lo: [0.004, 0.014, 0.0199], hi: [0.016, 0.026, 0.0201] }";

struct Truth {
  std::vector<Eigen::Matrix3Xd> markers;  // per measurement
  std::vector<Eigen::Vector3d> reaction;  // per measurement (one press each)
};

/// The truth's marker positions and reactions for the scenario at `file`.
Truth simulate(const path& file) {
  const Scenario s = load_scenario(file.string());
  ProbeExperiment ex(s, load_probing(s));
  Truth t;
  for (int m = 0; m < ex.size(); ++m) {
    const Eigen::Matrix3Xd x = ex.equilibrium(m);
    t.markers.push_back(marker_positions(s.mesh, s.markers.embedded, x));
    t.reaction.push_back(ex.reactions(m, x).at(0));
  }
  return t;
}

/// Writes measurement m's marker positions as an `observed` CSV.
std::string write_observed(const path& dir, const std::string& name, const Eigen::Matrix3Xd& at) {
  std::string csv = "name,x,y,z\n";
  const char* names = "abcdef";
  for (int j = 0; j < at.cols(); ++j)
    csv += fmt::format("{},{:.17g},{:.17g},{:.17g}\n", names[j], at(0, j), at(1, j), at(2, j));
  const path file = dir / (name + ".csv");
  test::write_text(file, csv);
  return file.string();
}

/// The two-press scenario with the truth's data: `with_reaction` gives each press
/// its measured force.
std::string observed_block(const path& dir, const Truth& t, bool with_reaction,
                           const std::string& material) {
  const Eigen::Vector3d depth[] = {{0, 0, -0.002}, {0.0005, 0, -0.001}};
  const char* names[] = {"centre", "left"};
  const std::string boxes[] = {kCentre, kLeft};
  std::string ms;
  for (int m = 0; m < 2; ++m) {
    const std::string reaction =
        with_reaction ? fmt::format(", reaction: [{:.17g}, {:.17g}, {:.17g}]", t.reaction[m].x(),
                                    t.reaction[m].y(), t.reaction[m].z())
                      : "";
    ms += press_entry(names[m], boxes[m], depth[m], reaction) +
          "      observed: " + write_observed(dir, names[m], t.markers[m]) + "\n";
  }
  return pressed_block(material, ms,
                       with_reaction ? "  noise: { markers: 5.0e-5, force: 0.01 }\n" : "");
}

Truth truth_data(const path& dir) {
  const std::string ms = press_entry("centre", kCentre, {0, 0, -0.002}, "") +
                         press_entry("left", kLeft, {0.0005, 0, -0.001}, "");
  test::write_text(dir / "truth.yaml", pressed_block(kTruth, ms));
  return simulate(dir / "truth.yaml");
}

}  // namespace

TEST(PressedProbe, ACompressedColumnWithoutPoissonEffectPushesBackWithEADeltaOverL) {
  // λ ≈ 0: no lateral strain, so the held faces at both ends do not matter and the
  // column is in uniaxial stress: R = E A δ / L exactly for a linear law (the patch
  // test: linear tetrahedra carry uniform strain exactly).
  const path dir = test::scratch("press-column");
  const double mu = 1e5, lambda = 1e-6, A = 1e-4, L = 0.1, delta = 1e-6;
  const std::string yaml =
      "name: column\n"
      "mesh: { generate: box, lo: [0, 0, 0], hi: [0.01, 0.01, 0.1], element_size: 0.005 }\n"
      "material:\n  density: 1000\n  elastic: { model: corotational, lambda: 1.0e-6, mu: 1.0e5 }\n"
      "gravity: [0, 0, 0]\n"
      "clamps: [{ name: base, select: { plane: { axis: z, at: 0 } } }]\n"
      "probing:\n  measurements:\n"
      "    - { name: squeeze, press: [{ name: plate, select: { plane: { axis: z, at: 0.1 } }, "
      "displacement: [0, 0, -1.0e-6] }] }\n";
  test::write_text(dir / "column.yaml", yaml);
  const Scenario s = load_scenario((dir / "column.yaml").string());
  ProbeExperiment ex(s, load_probing(s));
  const Eigen::Matrix3Xd x = ex.equilibrium(0);
  const Eigen::Vector3d R = ex.reactions(0, x).at(0);
  const double E = mu * (3 * lambda + 2 * mu) / (lambda + mu);
  EXPECT_NEAR(R.z(), -E * A * delta / L, 1e-6 * E * A * delta / L);
  EXPECT_NEAR(R.head<2>().norm(), 0, 1e-9 * E * A * delta / L);
  // The plate's nodes sit where it put them.
  for (int a = 0; a < s.mesh.num_nodes(); ++a) {
    if (std::abs(s.mesh.nodes(2, a) - L) < 1e-12) {
      EXPECT_NEAR(x(2, a), L - delta, 1e-15) << a;
    }
  }
  // The base holds the column with the opposite force.
  const ClampReaction base(ex.model(0), 0);
  Eigen::Vector3d support;
  ASSERT_TRUE(base.force(x, support));
  EXPECT_NEAR((support + R).norm(), 0, 1e-9 * R.norm());
}

TEST(PressedProbe, APressTooDeepForOneStepIsLoadedInStepsAndTheForcesBalance) {
  // 6 mm into a 20 mm block: the elements under the indenter would be inverted at
  // the full depth with the rest of the body at rest. Under gravity the table, the
  // indenter and the body's weight balance: Σ reactions + M g = 0.
  const path dir = test::scratch("press-deep");
  std::string yaml = pressed_block(kTruth, press_entry("deep", kCentre, {0, 0, -0.006}, ""));
  yaml.replace(yaml.find("gravity: [0, 0, 0]"), 18, "gravity: [0, 0, -9.81]");
  test::write_text(dir / "deep.yaml", yaml);
  const Scenario s = load_scenario((dir / "deep.yaml").string());
  ProbeExperiment ex(s, load_probing(s));
  const Eigen::Matrix3Xd x = ex.equilibrium(0);
  const Eigen::Vector3d R = ex.reactions(0, x).at(0);
  EXPECT_LT(R.z(), -0.5) << "a 30 % indentation of a 27 kPa foam pushes back by about a newton";
  const ClampReaction table(ex.model(0), 0);
  Eigen::Vector3d support;
  ASSERT_TRUE(table.force(x, support));
  const double weight = 60 * 0.04 * 0.04 * 0.02 * 9.81;
  EXPECT_NEAR((support + R + Eigen::Vector3d(0, 0, -weight)).norm(), 0, 1e-8 * R.norm());

  // Without gravity the press is the only load: the residual is measured against the
  // force it brings, not against the zero imbalance of the start at rest.
  test::write_text(dir / "weightless.yaml",
                   pressed_block(kTruth, press_entry("deep", kCentre, {0, 0, -0.006}, "")));
  const Scenario w = load_scenario((dir / "weightless.yaml").string());
  ProbeExperiment weightless(w, load_probing(w));
  Eigen::VectorXd x_free = rigid_initial_guess(weightless.model(0), 0);
  const StaticResult r = solve_static(weightless.model(0), 0, x_free);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(r.residual, 1e-9);
  EXPECT_GT(r.load_steps, 1);
}

TEST(PressedProbe, TheStaticTermsGradientAndRowsWithAMeasuredReactionMatchCentralDifferences) {
  const path dir = test::scratch("press-gradient");
  const Truth t = truth_data(dir);
  test::write_text(dir / "fit.yaml", observed_block(dir, t, true, kStart) +
                                         "fit:\n  parameters: [elastic.lambda, elastic.mu]\n");
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(s, s.fit.parameters);
  ASSERT_EQ(problem.num_static_terms(), 2);
  const Eigen::VectorXd p = problem.map().initial();
  for (int k = 0; k < 2; ++k) {
    StaticTerm& term = problem.static_term(k);
    const StaticTermResult at = term.evaluate(problem.map(), p, true);
    ASSERT_TRUE(at.ok) << at.error;
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    std::vector<std::pair<int, int>> where;
    std::string error;
    ASSERT_TRUE(term.residuals(problem.map(), p, true, r, J, where, error)) << error;
    ASSERT_EQ(r.size(), 6 * 3 + 3);  // six markers and one reaction
    EXPECT_EQ(where.back(), std::make_pair(-1, 2));
    // Φ_s = w/2 ‖r‖², the reaction's rows scaled by the noise ratio. Each call solves
    // the equilibrium again to 1e-10 of the load, and R − R̄ is a small difference of
    // forces: the two agree to that solve's tolerance, not to round-off.
    EXPECT_NEAR(0.5 * term.weight() * r.squaredNorm(), at.phi, 1e-8 * at.phi);
    const double scale = at.gradient.cwiseAbs().maxCoeff();
    for (int j = 0; j < p.size(); ++j) {
      const double h = 1e-5;
      Eigen::VectorXd up = p, down = p, r_up, r_down;
      up[j] += h, down[j] -= h;
      const double fd = (term.evaluate(problem.map(), up, false).phi -
                         term.evaluate(problem.map(), down, false).phi) /
                        (2 * h);
      EXPECT_NEAR(at.gradient[j], fd, 1e-6 * scale) << term.name() << " " << problem.map().label(j);
      Eigen::MatrixXd unused;
      ASSERT_TRUE(term.residuals(problem.map(), up, false, r_up, unused, where, error));
      ASSERT_TRUE(term.residuals(problem.map(), down, false, r_down, unused, where, error));
      const Eigen::VectorXd column = (r_up - r_down) / (2 * h);
      EXPECT_LT((J.col(j) - column).norm(), 1e-6 * J.norm()) << term.name() << " column " << j;
      // The reaction's rows move with the parameters: the force is measured.
      EXPECT_GT(J.col(j).tail<3>().norm(), 1e-3 * J.col(j).norm());
    }
  }
}

TEST(PressedProbe, AMeasuredForceSetsTheModuliScaleThatMarkersAloneCannot) {
  // Pressed to a depth with no gravity, the markers' positions do not change when
  // both moduli scale together: markers alone fix λ/μ only. The measured force
  // fixes the scale. Both fits start with λ 4× and μ 1.5× off.
  const path dir = test::scratch("press-scale");
  const Truth t = truth_data(dir);
  for (const bool with_reaction : {true, false}) {
    const path file = dir / (with_reaction ? "with.yaml" : "without.yaml");
    test::write_text(file, observed_block(dir, t, with_reaction, kStart));
    const Scenario s = load_scenario(file.string());
    ProbeExperiment ex(s, load_probing(s));
    std::vector<ObservedProbe> probes = ex.observed();
    const DisplacementInverseResult r = displacement_based_inverse(probes);
    const double lambda = r.q(0, 0), mu = r.q(1, 0);
    EXPECT_NEAR(lambda / mu, 2.0, 2e-4) << "with reaction " << with_reaction;
    EXPECT_LT(r.rms, 1e-9);
    if (with_reaction) {
      EXPECT_NEAR(mu, 1.0e4, 1e-4 * 1.0e4) << r.stop;
      EXPECT_NEAR(lambda, 2.0e4, 1e-4 * 2.0e4) << r.stop;
      EXPECT_LT(r.reaction_rms, 1e-6);
    } else {
      EXPECT_GT(std::abs(mu / 1.0e4 - 1), 0.1) << "the scale is not in the markers: " << mu;
    }
  }
}

TEST(PressedProbe, TheForceBasedInverseTakesTheMeasuredForceAsThreeMoreRows) {
  // Every node observed (the truth's equilibrium), a warped-stiffness truth: the
  // linear inverse recovers it exactly, its only load being the measured force.
  const path dir = test::scratch("press-force-inverse");
  const std::string warped = "  elastic: { model: corotational, lambda: 2.0e4, mu: 1.0e4 }";
  test::write_text(dir / "truth.yaml",
                   pressed_block(warped, press_entry("centre", kCentre, {0, 0, -0.002}, "")));
  const Scenario s = load_scenario((dir / "truth.yaml").string());
  ProbeExperiment ex(s, load_probing(s));
  const Eigen::Matrix3Xd x = ex.equilibrium(0);
  const Eigen::Vector3d R = ex.reactions(0, x).at(0);
  StaticState state{&ex.model(0), x, {}};
  ForceInverseOptions o;
  o.grouping = ElementGrouping::kGlobal;
  EXPECT_THROW(force_based_inverse({state}, o), Error) << "no force: nothing sets the scale";
  state.reactions.emplace_back(1, R);
  const ForceInverseResult r = force_based_inverse({state}, o);
  EXPECT_NEAR(r.q[0](0, 0), 2.0e4, 1e-6 * 2.0e4);
  EXPECT_NEAR(r.q[0](1, 0), 1.0e4, 1e-6 * 1.0e4);
  EXPECT_LT(r.relative_residual, 1e-8);
}

TEST(PressedProbe, BadPressEntriesAreNamedWithTheirPlace) {
  const path dir = test::scratch("press-errors");
  auto error_of = [&](const std::string& yaml) {
    test::write_text(dir / "bad.yaml", yaml);
    try {
      const Scenario s = load_scenario((dir / "bad.yaml").string());
      load_probing(s);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  auto expect_refused = [&](const std::string& measurements, const std::string& message) {
    const std::string error = error_of(pressed_block(kTruth, measurements));
    EXPECT_NE(error.find(message), std::string::npos) << error;
  };
  expect_refused(press_entry("p", kCentre, {0, 0, -1e-3}, ", reaction: [0, 0, -1]"),
                 "probing.measurements[0].press[0].reaction: a measured reaction needs "
                 "probing.noise");
  expect_refused(
      "    - { name: p, press: [{ select: { plane: { axis: z, at: 0 } }, displacement: "
      "[0, 0, 1.0e-3] }] }\n",
      "probing.measurements[0].press[0].select: node 0 is held by clamp 'table'");
  expect_refused("    - { name: p, press: [{ select: { box: " + kCentre +
                     " }, displacement: [0, 0, -1.0e-3] }], loads: [{ name: push, select: { "
                     "plane: { axis: z, at: 0.02 } }, force: [1, 0, 0] }] }\n",
                 "probing.measurements[0].press[0].select: node");
  expect_refused("    - { name: p }\n",
                 "probing.measurements[0]: give the probe as 'loads' (a force) or 'press'");
  expect_refused("    - { name: p, press: [{ select: { plane: { axis: z, at: 0.02 } } }] }\n",
                 "probing.measurements[0].press[0].displacement: missing required key");
}

TEST(PressedProbe, TheBundledExampleReadsItsPressesAndForces) {
  const Scenario s = load_scenario(KELVIN_SOURCE_DIR "/yaml/examples/probe-foam-pressed.yaml");
  const ProbingSpec spec = load_probing(s);
  ASSERT_EQ(spec.measurements.size(), 3u);
  EXPECT_DOUBLE_EQ(spec.reaction_weight(), (5e-5 / 0.01) * (5e-5 / 0.01));
  for (const auto& m : spec.measurements) {
    ASSERT_EQ(m.presses.size(), 1u) << m.name;
    EXPECT_TRUE(m.presses[0].reaction.allFinite()) << m.name;
    EXPECT_TRUE(m.observed.allFinite()) << m.name;
  }
}

TEST(PressCli, ProbeWritesTheReactionsAndProbeFitReportsTheirMisfit) {
  const path dir = test::scratch("press-cli");
  const Truth t = truth_data(dir);
  test::CliRun run =
      test::run_kelvin("probe " + (dir / "truth.yaml").string() + " -o " + (dir / "sim").string());
  ASSERT_EQ(run.exit_code, 0) << run.out;
  const std::string csv = test::read_text(dir / "sim" / "reactions.csv");
  EXPECT_EQ(csv.rfind("measurement,press,fx,fy,fz\ncentre,tip,", 0), 0u) << csv;
  EXPECT_NE(run.out.find("press 'tip': force on the body"), std::string::npos) << run.out;
  test::write_text(dir / "fit.yaml", observed_block(dir, t, true, kStart));
  run = test::run_kelvin("probe-fit " + (dir / "fit.yaml").string() + " -o " +
                         (dir / "fit").string());
  ASSERT_EQ(run.exit_code, 0) << run.out;
  EXPECT_NE(run.out.find("measured reactions: rms"), std::string::npos) << run.out;
  test::write_text(dir / "markers-only.yaml", observed_block(dir, t, false, kStart));
  run = test::run_kelvin("probe-fit " + (dir / "markers-only.yaml").string() + " -o " +
                         (dir / "fit2").string());
  ASSERT_EQ(run.exit_code, 0) << run.out;
  EXPECT_NE(run.out.find("nothing sets the moduli's scale (no gravity either)"), std::string::npos)
      << run.out;
}

}  // namespace kelvin
