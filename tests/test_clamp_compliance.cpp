// Compliant clamps (engine/clamp_spring.hpp): a hanging bar's clamp face sinks by
// its weight over the springs' stiffness and area, a tiny compliance reproduces the
// rigid clamp, the compliance's gradient agrees three ways, and the scenario refuses
// what has no meaning.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "adjoint/fit_problem.hpp"
#include "base/error.hpp"
#include "engine/csv.hpp"
#include "gradient_agreement.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

constexpr double kRho = 1000, kG = 9.81, kL = 0.1, kA = 0.02 * 0.02;

/// A bar hanging from its top face z = L; `clamp_keys` make that clamp compliant.
std::string hanging_bar(const std::string& clamp_keys) {
  return fmt::format(R"(
mesh: {{ generate: box, lo: [0, 0, 0], hi: [0.02, 0.02, {}], element_size: 0.01 }}
material:
  density: {}
  elastic: {{ model: neo-hookean, lambda: 1.0e3, mu: 1.0e5 }}
gravity: [0, 0, -{}]
initial: static
clamps:
  - name: top
    select: {{ plane: {{ axis: z, at: {} }} }}
    {}
time: {{ end: 0.01 }}
)",
                     kL, kRho, kG, kL, clamp_keys);
}

/// The static equilibrium of a scenario, as full nodal positions.
Eigen::Matrix3Xd static_positions(const fs::path& dir, const std::string& name,
                                  const std::string& yaml) {
  test::write_text(dir / (name + ".yaml"), yaml);
  const Scenario s = load_scenario((dir / (name + ".yaml")).string());
  const auto model = build_model(s);
  Eigen::VectorXd x0, v0;
  initial_state(s, *model, x0, v0);
  Eigen::Matrix3Xd x, v;
  model->expand(0, x0.data(), v0.data(), x, v);
  return x;
}

/// The shaken bar of test_support with its markers, clamp rigid.
test::ShakenBar shaken_bar() {
  test::ShakenBar b;
  b.material =
      "  density: 1100\n  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }\n"
      "  viscous: { model: newtonian, nu: 20 }";
  b.tail = test::kShakenBarMarkers;
  return b;
}

std::string refusal(const fs::path& dir, const std::string& yaml) {
  test::write_text(dir / "bad.yaml", yaml);
  try {
    load_scenario((dir / "bad.yaml").string());
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(ClampCompliance, AHangingBarsClampFaceSinksByItsWeightOverTheSpringStiffness) {
  const fs::path dir = test::scratch("clamp-compliance-static");
  const double k = 1e6;  // N/m³: a 1 mm sink under the bar's 981 Pa
  const Eigen::Matrix3Xd rigid = static_positions(dir, "rigid", hanging_bar(""));
  const Eigen::Matrix3Xd soft =
      static_positions(dir, "soft", hanging_bar(fmt::format("stiffness: {}", k)));
  const Eigen::Matrix3Xd X = load_scenario((dir / "soft.yaml").string()).mesh.nodes;
  const double sink = kRho * kG * kL / k;  // weight / (k A)
  // The springs carry the whole weight: the face's mean sink is exact. A bar this
  // nearly free of lateral contraction (Poisson ratio 0.005) hangs uniformly, so each node
  // of the face and the free end sink by about as much.
  int face = 0, free_end = 0;
  double tip_shift = 0;
  for (int a = 0; a < X.cols(); ++a) {
    if (std::abs(X(2, a) - kL) < 1e-9) {
      const double gap = soft(2, a) - X(2, a);
      EXPECT_NEAR(gap, -sink, 0.05 * sink) << "node " << a;
      ++face;
    }
    if (std::abs(X(2, a)) < 1e-9) {
      tip_shift += soft(2, a) - rigid(2, a);
      ++free_end;
    }
  }
  ASSERT_EQ(face, 9);
  EXPECT_NEAR(tip_shift / free_end, -sink, 0.02 * sink);
  // The exact balance: Σ S gap / c over the faces equals the weight, i.e. the
  // S-weighted mean sink is W c / A.
  const Scenario s = load_scenario((dir / "soft.yaml").string());
  const auto model = build_model(s);
  double weighted = 0, area = 0;
  for (const ClampFace& f : model->clamp_faces())
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        weighted += face_weight(f, a, b) * (soft(2, f.nodes[b]) - X(2, f.nodes[b]));
        area += face_weight(f, a, b);
      }
  EXPECT_NEAR(area, kA, 1e-15);
  EXPECT_NEAR(weighted / area, -sink, 1e-6 * sink);
}

TEST(ClampCompliance, ATinyComplianceReproducesTheRigidClampAndAModerateOneDoesNot) {
  const fs::path dir = test::scratch("clamp-compliance-limit");
  test::ShakenBar b = shaken_bar();
  const MarkerTracks rigid =
      read_marker_tracks(test::simulate_tracks(dir, "rigid", test::shaken_bar_yaml(b)));
  b.clamp_keys = "compliance: 1.0e-13\n    damping_time: 1.0e-4";
  const MarkerTracks tiny =
      read_marker_tracks(test::simulate_tracks(dir, "tiny", test::shaken_bar_yaml(b)));
  b.clamp_keys = "compliance: 2.0e-7\n    damping_time: 1.0e-4";
  const MarkerTracks soft =
      read_marker_tracks(test::simulate_tracks(dir, "soft", test::shaken_bar_yaml(b)));
  ASSERT_EQ(rigid.xyz.cols(), tiny.xyz.cols());
  // The bar's own compliance L/E is about 2e-7 m³/N: 1e-13 sinks its clamp by
  // nanometres, 2e-7 by a good fraction of its deflection.
  const double motion = (rigid.xyz.colwise() - rigid.xyz.col(0)).cwiseAbs().maxCoeff();
  EXPECT_GT(motion, 1e-3);
  EXPECT_LT((tiny.xyz - rigid.xyz).cwiseAbs().maxCoeff(), 1e-4 * motion);
  EXPECT_GT((soft.xyz - rigid.xyz).cwiseAbs().maxCoeff(), 0.05 * motion);
}

TEST(ClampCompliance, TheComplianceGradientAgreesThreeWays) {
  const fs::path dir = test::scratch("clamp-compliance-gradient");
  test::ShakenBar b = shaken_bar();
  const std::string tracks = test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(b));
  b.clamp_keys = "compliance: 1.5e-7\n    damping_time: 2.0e-4";
  b.tail = test::kShakenBarMarkers + "\n  observed: " + tracks + "\n";
  test::write_text(dir / "fit.yaml", test::shaken_bar_yaml(b));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(
      s, {positive_fit_parameter("clamps.base.compliance"), positive_fit_parameter("elastic.mu")});
  test::expect_gradients_agree(problem);
}

TEST(ClampCompliance, TheScenarioRefusesWhatHasNoMeaning) {
  const fs::path dir = test::scratch("clamp-compliance-refusals");
  EXPECT_NE(refusal(dir, hanging_bar("compliance: 1e-6\n    stiffness: 1e6")).find("not both"),
            std::string::npos);
  EXPECT_NE(refusal(dir, hanging_bar("compliance: 0")).find("clamps[0].compliance"),
            std::string::npos);
  EXPECT_NE(refusal(dir, hanging_bar("damping_time: 1e-4")).find("beside the clamp's springs"),
            std::string::npos);
  // An edge of the bar holds no face for the springs to act on.
  std::string edge = hanging_bar("compliance: 1e-6");
  edge.replace(edge.find("{ plane: { axis: z, at: 0.1 } }"),
               std::string("{ plane: { axis: z, at: 0.1 } }").size(),
               "{ box: { lo: [0, 0, 0.1], hi: [0.02, 0, 0.1] } }");
  const std::string e = refusal(dir, edge);
  EXPECT_NE(e.find("clamps[0].select"), std::string::npos) << e;
  EXPECT_NE(e.find("cover none"), std::string::npos) << e;
  // Fitting a rigid clamp's compliance names the clamp and the key it lacks.
  const std::string fit = refusal(dir, hanging_bar("") + R"(
markers:
  rest: [ { name: tip, at: [0.01, 0.01, 0] } ]
fit:
  parameters: [ clamps.top.compliance ]
)");
  EXPECT_NE(fit.find("clamp 'top' is rigid"), std::string::npos) << fit;
}

}  // namespace kelvin
