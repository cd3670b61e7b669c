// Shape targets (Real2Sim §5, Fig. 10): an objective term at a fixed time. Its value
// against the prescribed clamp motion, its gradient three ways at an interior time,
// at the end and at a static start, the same gradient with the run cut in segments,
// a fit that recovers a stiffness from the shape it produced, and the errors of a
// bad `targets:` entry.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <sstream>
#include <string>

#include "adjoint/fit_problem.hpp"
#include "base/error.hpp"
#include "engine/csv.hpp"
#include "fit/fit_loop.hpp"
#include "gradient_agreement.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

const std::string kMaterial = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })";

/// The shaken bar (0.06 × 0.02 × 0.02 m, clamped at x = 0) with `tail` appended.
std::string bar(const std::string& tail, const std::string& material = kMaterial,
                const std::string& name = "bar") {
  test::ShakenBar b;
  b.name = name;
  b.material = material.substr(1);
  b.rtol = 1e-9;
  b.atol = 1e-13;
  b.tail = tail;
  return test::shaken_bar_yaml(b);
}

/// A `fit:` section fitting μ with these `targets:` entries (YAML list lines).
std::string fit_targets(const std::string& entries) {
  return "\nfit:\n  parameters: [elastic.mu]\n  objective:\n    targets:" + entries;
}

Scenario load(const fs::path& dir, const std::string& name, const std::string& yaml) {
  test::write_text(dir / (name + ".yaml"), yaml);
  return load_scenario((dir / (name + ".yaml")).string());
}

/// The clamp's prescribed displacement along y and z at t (shaken_bar_yaml's motion).
Eigen::Vector2d clamp_offset(double t) {
  const double pi = std::numbers::pi;
  return {0.003 * std::sin(2 * pi * 17 * t - pi / 2), 0.002 * std::sin(2 * pi * 13 * t - pi / 2)};
}

ExperimentResult evaluate(FitProblem& problem, GradientMethod method, double segment = 0) {
  GradientOptions o;
  o.method = method;
  o.segment = segment;
  Evaluation ev = problem.evaluate(problem.map().initial(), o);
  EXPECT_TRUE(ev.ok) << ev.error;
  ExperimentResult r = ev.experiments.at(0);
  r.gradient = ev.gradient;
  return r;
}

}  // namespace

// The clamped face follows its prescribed motion, so a target on it has a value
// known in closed form at any time: w/2 · 9 nodes · the squared clamp offset.
TEST(ShapeTarget, ValueIsHalfTheWeightedSquaredDistanceAtItsTime) {
  const fs::path dir = test::scratch("shape-target-value");
  const Scenario s = load(dir, "s", bar(fit_targets(R"(
      - { name: start, time: 0, select: { plane: { axis: x, at: 0 } }, offset: [0, 0, 0], weight: 2 }
      - { name: middle, time: 0.037, select: { plane: { axis: x, at: 0 } }, plane: { axis: y, at: 0 } }
      - { name: end, time: 0.1, select: { plane: { axis: x, at: 0 } }, offset: [0, 0, 0], weight: 0.5 }
)")));
  ASSERT_EQ(s.fit.objective.targets.size(), 3u);
  EXPECT_EQ(s.fit.objective.targets[0].nodes.size(), 9u);
  FitProblem problem(s, {positive_fit_parameter("elastic.mu")});
  const ExperimentResult r = evaluate(problem, GradientMethod::kNone);
  ASSERT_EQ(r.phi_targets.size(), 3);
  EXPECT_NEAR(r.phi_targets[0], 2.0 / 2 * 9 * clamp_offset(0).squaredNorm(), 1e-15);
  // The plane y = 0 against the face's nodes at y = 0, 0.01, 0.02 (three of each) moved.
  double middle = 0;
  for (double y : {0.0, 0.01, 0.02}) middle += 3 * std::pow(y + clamp_offset(0.037)[0], 2);
  EXPECT_NEAR(r.phi_targets[1], 1.0 / 2 * middle, 1e-15);
  EXPECT_NEAR(r.phi_targets[2], 0.5 / 2 * 9 * clamp_offset(0.1).squaredNorm(), 1e-15);
  // Targets alone: Φ is their sum, and the RMS distance is over their coordinates.
  EXPECT_NEAR(r.phi, r.phi_targets.sum(), 1e-18);
  const double weight = 2 * 27 + 1 * 9 + 0.5 * 27;
  EXPECT_NEAR(r.rms, std::sqrt(2 * r.phi / weight), 1e-15);
}

// Targets on free nodes at an interior time and at the end, beside the marker
// misfit: adjoint (λx jumps at the target), forward sensitivities and central
// differences agree, and the Taylor remainder falls at rate 2.
TEST(ShapeTarget, GradientsAgreeThreeWaysBesideTheMarkers) {
  const fs::path dir = test::scratch("shape-target-gradient");
  const std::string tracks = test::simulate_tracks(dir, "truth", bar(test::kShakenBarMarkers));
  const Scenario s = load(dir, "fit",
                          bar(test::kShakenBarMarkers + "\n  observed: " + tracks + fit_targets(R"(
      - { time: 0.05, select: { plane: { axis: x, at: 0.06 } }, plane: { axis: y, at: 0.001 }, weight: 0.05 }
      - { time: 0.1, select: { box: { lo: [0.025, 0, 0], hi: [0.035, 0.02, 0.02] } }, offset: [0, 0.002, -0.001], weight: 0.02 }
)"),
                              R"(
  density: 1000
  elastic: { model: neo-hookean, lambda: 2.2e5, mu: 0.9e5 }
  viscous: { model: newtonian, nu: 25 })"));
  FitProblem problem(
      s, {positive_fit_parameter("elastic.mu"), positive_fit_parameter("elastic.lambda"),
          positive_fit_parameter("viscous.nu"), positive_fit_parameter("density")});
  test::expect_gradients_agree(problem);
}

// Targets alone (no captured tracks), one of them at t = 0 of a static start: the
// sag under gravity depends on the stiffness, so λx(t₀) carries it to K₀⁻ᵀ.
TEST(ShapeTarget, GradientsAgreeForTargetsAloneWithOneAtTheStaticStart) {
  const fs::path dir = test::scratch("shape-target-alone");
  const Scenario s = load(dir, "fit", bar(fit_targets(R"(
      - { name: sag, time: 0, select: { plane: { axis: x, at: 0.06 } }, plane: { axis: z, at: 0.0 } }
      - { name: swing, time: 0.06, select: { plane: { axis: x, at: 0.06 } }, offset: [0, 0.004, 0] }
)")));
  FitProblem problem(s, {positive_fit_parameter("elastic.mu"), positive_fit_parameter("viscous.nu"),
                         positive_fit_parameter("density")});
  EXPECT_EQ(problem.experiment(0).objective().num_markers(), 0);
  test::expect_gradients_agree(problem);
}

// Segment boundaries that do not fall on the target's time leave Φ and dΦ/dp as
// they are: the target's time is a boundary of its own.
TEST(ShapeTarget, SegmentsAroundTheTargetTimeGiveTheSameGradient) {
  const fs::path dir = test::scratch("shape-target-segments");
  const Scenario s = load(dir, "fit", bar(fit_targets(R"(
      - { time: 0.05, select: { plane: { axis: x, at: 0.06 } }, offset: [0, 0.003, 0.001] }
)")));
  FitProblem problem(s,
                     {positive_fit_parameter("elastic.mu"), positive_fit_parameter("viscous.nu")});
  const ExperimentResult one = evaluate(problem, GradientMethod::kAdjoint);
  const ExperimentResult cut = evaluate(problem, GradientMethod::kAdjoint, 0.013);
  EXPECT_EQ(cut.segments, 9);  // 8 of 0.013 s and the target's time
  EXPECT_NEAR(cut.phi, one.phi, 1e-6 * one.phi);
  EXPECT_LT((cut.gradient - one.gradient).norm(), 1e-5 * one.gradient.norm())
      << cut.gradient.transpose() << "\n"
      << one.gradient.transpose();
}

// The free end's shape at t = 0.05 s, taken from a run with μ = 1.0e5 Pa as a
// per-node target, brings a fit started at μ = 1.6e5 back to 1.0e5.
TEST(ShapeTarget, AFitRecoversTheStiffnessThatMadeTheTargetShape) {
  const fs::path dir = test::scratch("shape-target-recovery");
  const Scenario mesh_only = load(dir, "mesh", bar(""));
  const Mesh& mesh = mesh_only.mesh;
  std::string rest = "\nmarkers:\n  rest:\n";
  std::vector<int> face;
  for (int v = 0; v < mesh.num_nodes(); ++v)
    if (std::abs(mesh.nodes(0, v) - 0.06) < 1e-9) {
      face.push_back(v);
      rest += fmt::format("    - {{ name: n{}, at: [{:.17g}, {:.17g}, {:.17g}] }}\n", v,
                          mesh.nodes(0, v), mesh.nodes(1, v), mesh.nodes(2, v));
    }
  ASSERT_EQ(face.size(), 9u);
  const MarkerTracks truth = read_marker_tracks(test::simulate_tracks(dir, "truth", bar(rest)));
  const auto frame = std::find_if(truth.times.begin(), truth.times.end(),
                                  [](double t) { return std::abs(t - 0.05) < 1e-9; });
  ASSERT_NE(frame, truth.times.end());
  const long f = frame - truth.times.begin();
  std::string csv = "node,x,y,z\n";
  for (size_t i = 0; i < face.size(); ++i)
    csv += fmt::format("{},{:.17g},{:.17g},{:.17g}\n", face[i], truth.xyz(3 * i, f),
                       truth.xyz(3 * i + 1, f), truth.xyz(3 * i + 2, f));
  test::write_text(dir / "target.csv", csv);
  const Scenario s = load(dir, "fit",
                          bar(fit_targets(R"(
      - { time: 0.05, positions: target.csv }
)"),
                              R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.6e5 }
  viscous: { model: newtonian, nu: 20 })"));
  FitProblem problem(s, {positive_fit_parameter("elastic.mu")});
  FitOptions o;
  o.max_evaluations = 30;
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  ASSERT_GT(out.evaluations, 0);
  EXPECT_NEAR(problem.map().value(out.p, 0), 1.0e5, 1e-3 * 1.0e5)
      << out.stop_reason << " after " << out.evaluations << " evaluations";
}

// The bundled example (Real2Sim Fig. 10 on a coarse mesh): the per-element stiffness
// fit flattens the tilted bottom face, 1.88 mm from the level plane, to 0.1 mm.
TEST(ShapeTarget, TheBundledExampleFlattensTheBottomFace) {
  const fs::path out = test::scratch("shape-target-example");
  const test::CliRun r = test::run_kelvin(
      "fit " KELVIN_SOURCE_DIR "/yaml/examples/target-shape.yaml -q -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const std::string report = test::read_text(out / "report.md");
  const auto row = report.find("| target-shape | flat-bottom | 0.2 | 19 | ");
  ASSERT_NE(row, std::string::npos) << report;
  double before = 0, after = 0;
  ASSERT_EQ(std::sscanf(report.c_str() + row, "| target-shape | flat-bottom | 0.2 | 19 | %lf | %lf",
                        &before, &after),
            2);
  EXPECT_NEAR(before, 1.88, 0.01);
  EXPECT_LT(after, 0.2);

  // The field that does it (Real2Sim Fig. 10 found a stiff core and a soft rim):
  // stiffer in the core than at the rim, and stiff by the clamp, soft by the face.
  const Scenario s = load_scenario(KELVIN_SOURCE_DIR "/yaml/examples/target-shape.yaml");
  const Mesh& mesh = s.mesh;
  std::vector<double> mu(mesh.num_tets(), NAN);
  std::istringstream fields(test::read_text(out / "fitted-fields.csv"));
  std::string line;
  std::getline(fields, line);
  ASSERT_EQ(line, "element,elastic.mu");
  for (int e = 0; std::getline(fields, line); ++e) {
    ASSERT_LT(e, mesh.num_tets());
    mu[e] = std::stod(line.substr(line.find(',') + 1));
  }
  double core = 0, rim = 0, top = 0, bottom = 0;
  int n_core = 0, n_rim = 0, n_top = 0, n_bottom = 0;
  for (int e = 0; e < mesh.num_tets(); ++e) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) c += mesh.nodes.col(mesh.tets(k, e)) / 4;
    const double r = std::hypot(c.x(), c.y());
    if (r < 0.01) core += mu[e], ++n_core;
    if (r > 0.014) rim += mu[e], ++n_rim;
    if (c.z() > 0.08) top += mu[e], ++n_top;
    if (c.z() < 0.02) bottom += mu[e], ++n_bottom;
  }
  ASSERT_GT(n_core * n_rim * n_top * n_bottom, 0);
  EXPECT_GT(core / n_core, 1.1 * rim / n_rim);
  EXPECT_GT(top / n_top, 2 * bottom / n_bottom);
}

// The example's own gradient (720 per-element moduli): adjoint against central
// differences on twelve of them and along a random direction, Taylor rate 2. Φ is
// nearly linear along a direction of 720 random signs, so the Taylor steps start
// at 1 to rise above the integration noise.
TEST(ShapeTarget, TheBundledExamplePassesGradcheck) {
  const test::CliRun r =
      test::run_kelvin("gradcheck " KELVIN_SOURCE_DIR
                       "/yaml/examples/target-shape.yaml --no-forward --rtol 1e-7 --atol 1e-11 "
                       "--taylor-step 1");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("PASS: the gradient methods agree"), std::string::npos) << r.out;
}

// A run shortened after loading would leave the target unseen (Φ = 0, a check that
// passes on nothing): refused, naming the target.
TEST(ShapeTarget, ATargetAfterAShortenedRunIsRefused) {
  const test::CliRun r = test::run_kelvin(
      "gradcheck " KELVIN_SOURCE_DIR "/yaml/examples/target-shape.yaml --end 0.1 --no-forward");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("target-shape.yaml:34: fit.objective.targets: 'flat-bottom' at t = 0.2 s "
                       "lies after the end of the run (t = 0.1 s)"),
            std::string::npos)
      << r.out;
}

// A diagnosis explains a misfit to measurements: it refuses targets at once, before
// any fit, naming the line of the first one.
TEST(ShapeTarget, TheDiagnosisRefusesShapeTargets) {
  const fs::path out = test::scratch("shape-target-diagnose");
  const test::CliRun r = test::run_kelvin(
      "diagnose " KELVIN_SOURCE_DIR "/yaml/examples/target-shape.yaml -o " + out.string());
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("target-shape.yaml:34: fit.objective.targets: a diagnosis explains"),
            std::string::npos)
      << r.out;
}

// Targets in a further experiment of the fit are refused too, in that file.
TEST(ShapeTarget, TheDiagnosisRefusesTargetsOfAFurtherExperiment) {
  const fs::path dir = test::scratch("shape-target-diagnose-experiment");
  test::write_text(dir / "other.yaml", bar(R"(
fit:
  parameters: [elastic.mu]
  objective:
    targets: [ { time: 0.05, select: { plane: { axis: x, at: 0.06 } }, offset: [0, 0, 0] } ]
)"));
  test::write_text(dir / "main.yaml", bar(R"(
fit:
  parameters: [elastic.mu]
  experiments: [other.yaml]
)"));
  const test::CliRun r = test::run_kelvin("diagnose " + (dir / "main.yaml").string() + " -o " +
                                          (dir / "out").string());
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("other.yaml:"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("fit.objective.targets: a diagnosis explains"), std::string::npos) << r.out;
}

// Each mistake is named with the file, line and key.
TEST(ShapeTarget, BadTargetsAreRefusedWithTheKeyAndWhy) {
  const fs::path dir = test::scratch("shape-target-bad");
  test::write_text(dir / "dup.csv", "node,x,y,z\n3,0,0,0\n3,0,0,1\n");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"{ time: 0.2, select: { plane: { axis: x, at: 0 } }, offset: [0, 0, 0] }",
       "fit.objective.targets[0].time: 0.2 s is after the end of the run (time.end = 0.1 s)"},
      {"{ time: 0.05, select: { plane: { axis: x, at: 0.5 } }, offset: [0, 0, 0] }",
       "fit.objective.targets[0].select"},
      {"{ time: 0.05, select: { plane: { axis: x, at: 0 } }, offset: [0, 0, 0], plane: { axis: "
       "z, at: 0 } }",
       "fit.objective.targets[0].plane: give 'offset'"},
      {"{ time: 0.05, select: { plane: { axis: x, at: 0 } } }",
       "fit.objective.targets[0]: says no target shape"},
      {"{ time: 0.05, positions: dup.csv }", "dup.csv:3: node 3 appears twice (first on line 2)"},
      {"{ time: 0.05, positions: dup.csv, select: { plane: { axis: x, at: 0 } } }",
       "fit.objective.targets[0].select: a target given by 'positions'"},
      {"{ time: -1, select: { plane: { axis: x, at: 0 } }, offset: [0, 0, 0] }",
       "fit.objective.targets[0].time"},
      {"{ time: 0.05, select: { plane: { axis: x, at: 0 } }, offset: [0, 0, 0], weight: 0 }",
       "fit.objective.targets[0].weight"},
      {"{ time: 0.05, select: { plane: { axis: x, at: 0 } }, offset: [0, 0, 0], shape: flat }",
       "fit.objective.targets[0].shape"},
  };
  for (const auto& [entry, message] : cases) {
    test::write_text(
        dir / "s.yaml",
        bar("\nfit:\n  parameters: [elastic.mu]\n  objective:\n    targets:\n      - " + entry +
            "\n"));
    try {
      load_scenario((dir / "s.yaml").string());
      ADD_FAILURE() << "accepted: " << entry;
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(message), std::string::npos) << entry << "\n" << what;
      EXPECT_NE(what.find("s.yaml:"), std::string::npos) << what;
    }
  }
}

}  // namespace kelvin
