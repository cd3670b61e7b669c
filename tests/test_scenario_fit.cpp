// The `fit:` section of scenario files: a complete section resolves to what it says,
// defaults come from the model's ParamInfo, and each class of mistake is refused
// with a message naming the file, the line and the key path.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "base/error.hpp"
#include "yaml/scenario.hpp"

using namespace kelvin;
namespace fs = std::filesystem;

namespace {

/// A small bar with two markers. The `fit:` key is on line 8, so the first line of
/// the fit body is line 9. `viscous` = false blanks line 5, `markers` = false line 6
/// (the numbering stays the same).
std::string base(bool viscous = true, bool markers = true) {
  return std::string("mesh: { generate: box, size: [0.1, 0.02, 0.02], element_size: 0.01 }\n") +
         "material:\n"
         "  density: 900\n"
         "  elastic: { model: neo-hookean, lambda: 2.0e4, mu: 1.0e4 }\n" +
         (viscous ? "  viscous: { model: newtonian, nu: 5 }\n" : "  # no viscous term\n") +
         (markers ? "markers: { rest: [ { name: tip, at: [0.1, 0.01, 0.01] }, "
                    "{ name: base, at: [0.0, 0.01, 0.01] } ] }\n"
                  : "# no markers\n") +
         "time: { end: 1.0 }\n";
}

class FitSection : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("kelvin_test_scenario_fit_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// Writes `text` as <dir>/<name> and returns its path.
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path path = dir_ / name;
    std::ofstream(path) << text;
    return path.string();
  }
  /// The base scenario followed by `fit:` and `body`.
  Scenario load(const std::string& body, bool viscous = true, bool markers = true) const {
    return load_scenario(write("fit.yaml", base(viscous, markers) + "fit:\n" + body));
  }
  /// Loads base + fit body and checks that the refusal names fit.yaml:<line>: and
  /// contains every part.
  void expect_refused(const std::string& body, int line, const std::vector<std::string>& parts,
                      bool viscous = true, bool markers = true) const {
    const std::string path = write("fit.yaml", base(viscous, markers) + "fit:\n" + body);
    try {
      load_scenario(path);
      ADD_FAILURE() << "accepted:\n" << body;
    } catch (const Error& e) {
      const std::string msg = e.what();
      const std::string where = path + ":" + std::to_string(line) + ":";
      EXPECT_EQ(msg.rfind(where, 0), 0u) << "message: " << msg << "\ndoes not begin with " << where;
      for (const auto& p : parts)
        EXPECT_NE(msg.find(p), std::string::npos) << "message: " << msg << "\nlacks: " << p;
    }
  }

  fs::path dir_;
};

const std::string kOneParam = "  parameters: [ { target: elastic.mu } ]\n";

}  // namespace

// ---- accepted -------------------------------------------------------------------

TEST_F(FitSection, FullSectionResolves) {
  write("other-motion.yaml", base());
  const Scenario s = load(
      "  parameters:\n"
      "    - { target: elastic.mu, initial: 2.0e4, lower: 1.0e3, upper: 1.0e6, log: true, "
      "scope: global }\n"
      "    - { target: viscous.nu, scope: per-region }\n"
      "    - { target: density, scope: per-element }\n"
      "    - { target: elastic.lambda, scope: { boxes: [ { min: [0, 0, 0], max: [0.1, 0.1, "
      "0.05] } ] } }\n"
      "  objective: { weights: { tip: 2.0, base: 0 }, window: [0.1, 0.9] }\n"
      "  gradient: forward\n"
      "  algorithm: mma\n"
      "  max_evaluations: 50\n"
      "  ftol_rel: 1.0e-9\n"
      "  xtol_rel: 1.0e-7\n"
      "  max_seconds: 3600\n"
      "  smoothness: 0.5\n"
      "  lcurve: [1.0e-6, 1.0e-4]\n"
      "  experiments: [other-motion.yaml]\n"
      "  checkpoint_steps: 20\n"
      "  segment: 0.25\n");
  const FitSpec& f = s.fit;
  EXPECT_TRUE(f.present);
  ASSERT_EQ(f.parameters.size(), 4u);
  using Scope = FitParameterSpec::Scope;

  const auto& mu = f.parameters[0];
  EXPECT_EQ(mu.target, "elastic.mu");
  EXPECT_EQ(mu.scope, Scope::Global);
  ASSERT_TRUE(mu.initial.has_value());
  EXPECT_DOUBLE_EQ(*mu.initial, 2e4);
  EXPECT_DOUBLE_EQ(mu.lower, 1e3);
  EXPECT_DOUBLE_EQ(mu.upper, 1e6);
  EXPECT_TRUE(mu.log);
  EXPECT_EQ(mu.line, 10);

  const auto& nu = f.parameters[1];
  EXPECT_EQ(nu.target, "viscous.nu");
  EXPECT_EQ(nu.scope, Scope::PerRegion);
  EXPECT_FALSE(nu.initial.has_value());
  EXPECT_EQ(nu.line, 11);

  const auto& rho = f.parameters[2];
  EXPECT_EQ(rho.target, "density");
  EXPECT_EQ(rho.scope, Scope::PerElement);
  EXPECT_DOUBLE_EQ(rho.lower, 0);
  EXPECT_DOUBLE_EQ(rho.upper, 1e300);
  EXPECT_TRUE(rho.log);
  EXPECT_EQ(rho.line, 12);

  const auto& lambda = f.parameters[3];
  EXPECT_EQ(lambda.scope, Scope::Boxes);
  ASSERT_EQ(lambda.boxes.size(), 1u);
  EXPECT_TRUE(lambda.boxes[0].first.isZero());
  EXPECT_DOUBLE_EQ(lambda.boxes[0].second.z(), 0.05);
  EXPECT_EQ(lambda.line, 13);

  EXPECT_EQ(f.objective.weights.size(), 2u);
  EXPECT_DOUBLE_EQ(f.objective.weights.at("tip"), 2.0);
  EXPECT_DOUBLE_EQ(f.objective.weights.at("base"), 0.0);
  EXPECT_DOUBLE_EQ(f.objective.window_begin, 0.1);
  EXPECT_DOUBLE_EQ(f.objective.window_end, 0.9);
  EXPECT_EQ(f.gradient, "forward");
  EXPECT_EQ(f.algorithm, "mma");
  EXPECT_EQ(f.max_evaluations, 50);
  EXPECT_DOUBLE_EQ(f.ftol_rel, 1e-9);
  EXPECT_DOUBLE_EQ(f.xtol_rel, 1e-7);
  EXPECT_DOUBLE_EQ(f.max_seconds, 3600);
  EXPECT_DOUBLE_EQ(f.smoothness, 0.5);
  EXPECT_EQ(f.lcurve, (std::vector<double>{1e-6, 1e-4}));
  ASSERT_EQ(f.experiments.size(), 1u);
  EXPECT_TRUE(fs::equivalent(f.experiments[0], dir_ / "other-motion.yaml"));
  EXPECT_EQ(f.checkpoint_steps, 20);
  EXPECT_DOUBLE_EQ(f.segment, 0.25);
}

TEST_F(FitSection, DefaultsComeFromTheModel) {
  const Scenario s = load(
      "  parameters:\n"
      "    - elastic.mu\n"
      "    - { target: density }\n"
      "    - { target: viscous.nu, log: false }\n");
  const FitSpec& f = s.fit;
  EXPECT_TRUE(f.present);
  ASSERT_EQ(f.parameters.size(), 3u);
  // neo-hookean mu: [0, 1e300], strictly positive → log.
  EXPECT_EQ(f.parameters[0].target, "elastic.mu");
  EXPECT_EQ(f.parameters[0].scope, FitParameterSpec::Scope::Global);
  EXPECT_DOUBLE_EQ(f.parameters[0].lower, 0);
  EXPECT_DOUBLE_EQ(f.parameters[0].upper, 1e300);
  EXPECT_TRUE(f.parameters[0].log);
  EXPECT_FALSE(f.parameters[0].initial.has_value());
  EXPECT_EQ(f.parameters[0].line, 10);
  EXPECT_TRUE(f.parameters[1].log);
  EXPECT_DOUBLE_EQ(f.parameters[1].lower, 0);
  EXPECT_FALSE(f.parameters[2].log);
  EXPECT_TRUE(f.objective.weights.empty());
  EXPECT_DOUBLE_EQ(f.objective.window_begin, 0);
  EXPECT_LT(f.objective.window_end, 0);
  EXPECT_EQ(f.gradient, "adjoint");
  EXPECT_EQ(f.algorithm, "lbfgs");
  EXPECT_EQ(f.max_evaluations, 200);
  EXPECT_DOUBLE_EQ(f.ftol_rel, 1e-10);
  EXPECT_DOUBLE_EQ(f.xtol_rel, 1e-8);
  EXPECT_DOUBLE_EQ(f.max_seconds, 0);
  EXPECT_DOUBLE_EQ(f.smoothness, 0);
  EXPECT_TRUE(f.lcurve.empty());
  EXPECT_TRUE(f.experiments.empty());
  EXPECT_EQ(f.checkpoint_steps, 0);
  EXPECT_DOUBLE_EQ(f.segment, 0);
}

TEST_F(FitSection, AbsentSectionIsNotPresent) {
  const Scenario s = load_scenario(write("nofit.yaml", base()));
  EXPECT_FALSE(s.fit.present);
  EXPECT_TRUE(s.fit.parameters.empty());
}

TEST_F(FitSection, BobyqaWithoutGradientKeyGetsGradientNone) {
  const Scenario s = load(kOneParam + "  algorithm: bobyqa\n");
  EXPECT_EQ(s.fit.algorithm, "bobyqa");
  EXPECT_EQ(s.fit.gradient, "none");
  const Scenario t = load(kOneParam + "  algorithm: bobyqa\n  gradient: none\n");
  EXPECT_EQ(t.fit.gradient, "none");
}

TEST_F(FitSection, PerRegionOnASingleRegionMeshIsAccepted) {
  const Scenario s = load("  parameters: [ { target: elastic.mu, scope: per-region } ]\n");
  EXPECT_EQ(s.fit.parameters[0].scope, FitParameterSpec::Scope::PerRegion);
}

TEST_F(FitSection, SameTargetWithDifferentScopesIsAccepted) {
  const Scenario s = load(
      "  parameters:\n"
      "    - { target: elastic.mu }\n"
      "    - { target: elastic.mu, scope: per-element }\n");
  EXPECT_EQ(s.fit.parameters.size(), 2u);
}

// ---- refused: the parameter list ------------------------------------------------

TEST_F(FitSection, MissingParameters) {
  expect_refused("  algorithm: lbfgs\n", 9,
                 {"fit.parameters", "missing required key 'parameters'"});
}

TEST_F(FitSection, EmptyParameters) {
  expect_refused("  parameters: []\n", 9,
                 {"fit.parameters", "at least one parameter", "elastic.mu"});
}

TEST_F(FitSection, ParametersNotAList) {
  expect_refused("  parameters: { target: elastic.mu }\n", 9, {"fit.parameters", "list"});
}

TEST_F(FitSection, UnknownTargetSuggests) {
  expect_refused("  parameters:\n    - { target: elastic.mue }\n", 10,
                 {"fit.parameters[0].target", "'elastic.mue'", "did you mean 'elastic.mu'?",
                  "elastic.lambda", "viscous.nu", "density"});
}

TEST_F(FitSection, UnknownTargetInShorthand) {
  expect_refused("  parameters: [ plastic.mu ]\n", 9, {"fit.parameters[0]", "'plastic.mu'"});
}

TEST_F(FitSection, ViscousTargetWithoutViscousTerm) {
  expect_refused("  parameters:\n    - { target: viscous.nu }\n", 10,
                 {"fit.parameters[0].target", "no viscous term", "elastic.mu"},
                 /*viscous=*/false);
}

TEST_F(FitSection, DuplicateTargetAndScope) {
  expect_refused(
      "  parameters:\n"
      "    - { target: elastic.mu, scope: per-element }\n"
      "    - { target: viscous.nu }\n"
      "    - { target: elastic.mu, scope: per-element, lower: 10 }\n",
      12, {"fit.parameters[2]", "'elastic.mu'", "per-element", "line 10"});
}

TEST_F(FitSection, UnknownParameterKeySuggests) {
  expect_refused("  parameters:\n    - { target: elastic.mu, uper: 10 }\n", 10,
                 {"fit.parameters[0].uper", "did you mean 'upper'?"});
}

TEST_F(FitSection, MissingTarget) {
  expect_refused("  parameters:\n    - { lower: 10 }\n", 10,
                 {"fit.parameters[0].target", "missing required key 'target'"});
}

TEST_F(FitSection, InitialOutsideBounds) {
  expect_refused(
      "  parameters:\n    - { target: elastic.mu, initial: 5.0e6, lower: 1.0e3, upper: 1.0e6 }\n",
      10, {"fit.parameters[0].initial", "5e+06", "outside"});
}

TEST_F(FitSection, LowerNotBelowUpper) {
  expect_refused("  parameters:\n    - { target: elastic.mu, lower: 1.0e5, upper: 1.0e4 }\n", 10,
                 {"fit.parameters[0].upper", "must be below upper"});
}

TEST_F(FitSection, LowerOutsideTheModelsRange) {
  expect_refused("  parameters:\n    - { target: elastic.mu, lower: -5, log: false }\n", 10,
                 {"fit.parameters[0].lower", "admissible range", "'elastic.mu'"});
}

TEST_F(FitSection, ScaleIsAPositiveSizeOfALinearParameter) {
  const Scenario s =
      load("  parameters:\n    - { target: elastic.mu, log: false, scale: 2.0e4 }\n");
  EXPECT_EQ(s.fit.parameters[0].scale, 2.0e4);
  expect_refused("  parameters:\n    - { target: elastic.mu, log: false, scale: -3 }\n", 10,
                 {"fit.parameters[0].scale", "must be positive (got -3)"});
  expect_refused("  parameters:\n    - { target: elastic.mu, scale: 1.0e4 }\n", 10,
                 {"fit.parameters[0].scale", "log space", "log: false"});
}

TEST_F(FitSection, LogWithNegativeLower) {
  expect_refused("  parameters:\n    - { target: elastic.mu, lower: -1, log: true }\n", 10,
                 {"fit.parameters[0].lower", "log-transformed", "set log: false"});
}

TEST_F(FitSection, LogOnAParameterThatMayBeNegative) {
  // strain-damping d1 has the range (-inf, inf): log needs an explicit lower bound.
  const std::string path =
      write("fit.yaml",
            "mesh: { generate: box, size: [0.1, 0.02, 0.02], element_size: 0.01 }\n"
            "material:\n"
            "  density: 900\n"
            "  elastic: { model: neo-hookean }\n"
            "  viscous: { model: strain-damping, d1: 0.5 }\n"
            "time: { end: 1.0 }\n"
            "fit:\n"
            "  parameters:\n"
            "    - { target: viscous.d1, log: true }\n");
  try {
    load_scenario(path);
    ADD_FAILURE() << "accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(path + ":9:", 0), 0u) << msg;
    EXPECT_NE(msg.find("fit.parameters[0].log"), std::string::npos) << msg;
    EXPECT_NE(msg.find("lower: 0"), std::string::npos) << msg;
  }
}

TEST_F(FitSection, ScenarioValueOutsideBoundsWithoutInitial) {
  expect_refused("  parameters:\n    - { target: elastic.mu, lower: 1.0e5 }\n", 10,
                 {"fit.parameters[0]", "scenario's value 10000", "give 'initial'"});
}

TEST_F(FitSection, LogNotABoolean) {
  expect_refused("  parameters:\n    - { target: elastic.mu, log: maybe }\n", 10,
                 {"fit.parameters[0].log", "true or false"});
}

TEST_F(FitSection, UnknownScopeSuggests) {
  expect_refused("  parameters:\n    - { target: elastic.mu, scope: per-elemnt }\n", 10,
                 {"fit.parameters[0].scope", "did you mean 'per-element'?"});
}

TEST_F(FitSection, EmptyBoxList) {
  expect_refused("  parameters:\n    - { target: elastic.mu, scope: { boxes: [] } }\n", 10,
                 {"fit.parameters[0].scope.boxes", "at least one box"});
}

TEST_F(FitSection, BoxMinNotBelowMax) {
  expect_refused(
      "  parameters:\n"
      "    - target: elastic.mu\n"
      "      scope:\n"
      "        boxes:\n"
      "          - { min: [0, 0, 0], max: [0.1, 0.1, 0.05] }\n"
      "          - { min: [0, 0, 0.05], max: [0.1, 0.1, 0.05] }\n",
      14, {"fit.parameters[0].scope.boxes[1].max", "max.z = 0.05 is not above min.z = 0.05"});
}

TEST_F(FitSection, UnknownScopeMapKey) {
  expect_refused("  parameters:\n    - { target: elastic.mu, scope: { box: [] } }\n", 10,
                 {"fit.parameters[0].scope.box", "did you mean 'boxes'?"});
}

// ---- refused: objective ---------------------------------------------------------

TEST_F(FitSection, WeightForUnknownMarkerSuggests) {
  expect_refused(kOneParam + "  objective:\n    weights: { tip: 1, bsae: 2 }\n", 11,
                 {"fit.objective.weights.bsae", "not a marker", "did you mean 'base'?"});
}

TEST_F(FitSection, WeightWithoutMarkers) {
  expect_refused(kOneParam + "  objective:\n    weights: { tip: 1 }\n", 11,
                 {"fit.objective.weights.tip", "no markers"}, true, /*markers=*/false);
}

TEST_F(FitSection, NegativeWeight) {
  expect_refused(kOneParam + "  objective:\n    weights: { tip: -1 }\n", 11,
                 {"fit.objective.weights.tip", "must not be negative"});
}

TEST_F(FitSection, WindowReversed) {
  expect_refused(kOneParam + "  objective:\n    window: [0.5, 0.2]\n", 11,
                 {"fit.objective.window[1]", "must end after it begins"});
}

TEST_F(FitSection, WindowBeyondTheRun) {
  expect_refused(kOneParam + "  objective:\n    window: [0.1, 2.0]\n", 11,
                 {"fit.objective.window[1]", "time.end = 1 s"});
}

TEST_F(FitSection, WindowNegativeBegin) {
  expect_refused(kOneParam + "  objective:\n    window: [-0.1, 0.5]\n", 11,
                 {"fit.objective.window[0]", "must not be negative"});
}

TEST_F(FitSection, WindowNotAPair) {
  expect_refused(kOneParam + "  objective:\n    window: [0.1, 0.2, 0.3]\n", 11,
                 {"fit.objective.window", "two times"});
}

TEST_F(FitSection, UnknownObjectiveKey) {
  expect_refused(kOneParam + "  objective:\n    weigths: { tip: 1 }\n", 11,
                 {"fit.objective.weigths", "did you mean 'weights'?"});
}

// ---- refused: optimiser ---------------------------------------------------------

TEST_F(FitSection, UnknownFitKeySuggests) {
  expect_refused(kOneParam + "  max_evaluation: 10\n", 10,
                 {"fit.max_evaluation", "did you mean 'max_evaluations'?"});
}

TEST_F(FitSection, BobyqaWithAGradient) {
  expect_refused(kOneParam + "  algorithm: bobyqa\n  gradient: adjoint\n", 11,
                 {"fit.gradient", "bobyqa", "derivative-free"});
}

TEST_F(FitSection, GradientNoneWithAGradientAlgorithm) {
  expect_refused(kOneParam + "  gradient: none\n", 10,
                 {"fit.gradient", "lbfgs needs gradients", "bobyqa"});
  expect_refused(kOneParam + "  algorithm: slsqp\n  gradient: none\n", 11,
                 {"fit.gradient", "slsqp needs gradients"});
}

TEST_F(FitSection, UnknownAlgorithmSuggests) {
  expect_refused(kOneParam + "  algorithm: lbgfs\n", 10,
                 {"fit.algorithm", "did you mean 'lbfgs'?"});
}

TEST_F(FitSection, UnknownGradient) {
  expect_refused(kOneParam + "  gradient: adjiont\n", 10,
                 {"fit.gradient", "did you mean 'adjoint'?"});
}

TEST_F(FitSection, MaxEvaluationsBelowOne) {
  expect_refused(kOneParam + "  max_evaluations: 0\n", 10, {"fit.max_evaluations", "at least 1"});
}

TEST_F(FitSection, MaxEvaluationsNotWhole) {
  expect_refused(kOneParam + "  max_evaluations: 2.5\n", 10,
                 {"fit.max_evaluations", "whole number"});
}

TEST_F(FitSection, NegativeTolerances) {
  expect_refused(kOneParam + "  ftol_rel: -1.0e-8\n", 10, {"fit.ftol_rel", "must not be negative"});
  expect_refused(kOneParam + "  xtol_rel: -1\n", 10, {"fit.xtol_rel", "must not be negative"});
  expect_refused(kOneParam + "  max_seconds: -5\n", 10,
                 {"fit.max_seconds", "must not be negative"});
}

// A scenario integrating at rtol 1e-6: the fit's first stage runs at 1e-4 by
// default, at fit.start_rtol when given, and never looser than 1e-3.
TEST_F(FitSection, StartRtolSetsTheFirstStage) {
  auto at_1e6 = [this](const std::string& body) {
    return load_scenario(write("fit.yaml", base() + "solver: { rtol: 1.0e-6 }\nfit:\n" + body));
  };
  EXPECT_DOUBLE_EQ(fit_start_tolerance_scale(at_1e6(kOneParam)), 100);
  EXPECT_DOUBLE_EQ(fit_start_tolerance_scale(at_1e6(kOneParam + "  start_rtol: 1.0e-5\n")), 10);
  EXPECT_DOUBLE_EQ(fit_start_tolerance_scale(at_1e6(kOneParam + "  start_rtol: 1.0e-6\n")), 1);
  Scenario loose = at_1e6(kOneParam);
  loose.solver.rtol = 1e-4;
  EXPECT_DOUBLE_EQ(fit_start_tolerance_scale(loose), 10);
  loose.solver.rtol = 1e-2;
  EXPECT_DOUBLE_EQ(fit_start_tolerance_scale(loose), 1);
}

TEST_F(FitSection, StartRtolOutsideItsRange) {
  expect_refused(kOneParam + "  start_rtol: 1.0e-5\n", 10,
                 {"fit.start_rtol", "[solver.rtol, 1)", "0.0001"});
  expect_refused(kOneParam + "  start_rtol: 1\n", 10, {"fit.start_rtol", "[solver.rtol, 1)"});
}

TEST_F(FitSection, NegativeSmoothness) {
  expect_refused(kOneParam + "  smoothness: -0.1\n", 10,
                 {"fit.smoothness", "must not be negative"});
}

TEST_F(FitSection, LcurveValueNotPositive) {
  expect_refused(kOneParam + "  lcurve: [1.0e-6, 0]\n", 10, {"fit.lcurve[1]", "must be positive"});
}

TEST_F(FitSection, MissingExperimentFile) {
  expect_refused(kOneParam + "  experiments: [ nowhere.yaml ]\n", 10,
                 {"fit.experiments[0]", "no such file 'nowhere.yaml'"});
}

TEST_F(FitSection, NegativeCheckpointSteps) {
  expect_refused(kOneParam + "  checkpoint_steps: -1\n", 10,
                 {"fit.checkpoint_steps", "must not be negative"});
}

TEST_F(FitSection, NegativeSegment) {
  expect_refused(kOneParam + "  segment: -0.1\n", 10, {"fit.segment", "must not be negative"});
}
