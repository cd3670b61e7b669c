// Scenario loading: the bundled examples resolve to what they say, and each class
// of input error is refused with a message that points at the file, line:column
// and key path and says why.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "base/error.hpp"
#include "yaml/scenario.hpp"
#include "yaml/yaml_util.hpp"

using namespace kelvin;

namespace {

std::string example(const std::string& name) {
  return std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/" + name;
}
std::string fixture(const std::string& name) {
  return std::string(KELVIN_TEST_DATA) + "/scenarios/" + name;
}

/// Loads a malformed fixture and checks that the message contains every part.
void expect_refused(const std::string& name, const std::vector<std::string>& parts) {
  SCOPED_TRACE(name);
  try {
    load_scenario(fixture(name));
    ADD_FAILURE() << name << " was accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    for (const auto& p : parts)
      EXPECT_NE(msg.find(p), std::string::npos) << "message: " << msg << "\nlacks: " << p;
  }
}

double weight_sum(const MarkerEmbedding& m) {
  return m.weights.sum();
}

}  // namespace

TEST(ScenarioExamples, CantileverGravity) {
  const Scenario s = load_scenario(example("cantilever-gravity.yaml"));
  EXPECT_EQ(s.name, "cantilever-gravity");
  EXPECT_GT(s.mesh.num_nodes(), 0);
  EXPECT_GT(s.mesh.num_tets(), 0);
  EXPECT_NEAR(s.mesh.nodes.row(0).maxCoeff(), 0.2, 1e-12);
  EXPECT_DOUBLE_EQ(s.material.density, 1000);
  EXPECT_EQ(s.material.elastic[0].model, "neo-hookean");
  // E = 1e6, nu = 0.3 converted to Lamé parameters.
  EXPECT_NEAR(s.material.elastic[0].params.at("lambda"), 1e6 * 0.3 / (1.3 * 0.4), 1e-6);
  EXPECT_NEAR(s.material.elastic[0].params.at("mu"), 1e6 / 2.6, 1e-6);
  EXPECT_EQ(s.material.elastic[0].params.count("E"), 0u);
  ASSERT_EQ(s.material.viscous.size(), 1u);
  EXPECT_EQ(s.material.viscous[0].model, "newtonian");
  EXPECT_DOUBLE_EQ(s.material.viscous[0].params.at("nu"), 5);
  EXPECT_DOUBLE_EQ(s.gravity.z(), -9.81);
  EXPECT_FALSE(s.static_initial);
  ASSERT_EQ(s.clamps.size(), 1u);
  EXPECT_EQ(s.clamps[0].name, "wall");
  ASSERT_FALSE(s.clamps[0].nodes.empty());
  for (int i : s.clamps[0].nodes) EXPECT_NEAR(s.mesh.nodes(0, i), 0.0, 1e-9);
  ASSERT_TRUE(s.clamps[0].motion);
  EXPECT_NE(dynamic_cast<const FixedMotion*>(s.clamps[0].motion.get()), nullptr);
  ASSERT_EQ(s.markers.embedded.size(), 2u);
  EXPECT_EQ(s.markers.embedded[0].name, "tip");
  EXPECT_EQ(s.markers.embedded[1].name, "mid");
  for (const auto& m : s.markers.embedded) {
    EXPECT_GE(m.tet, 0);
    EXPECT_LT(m.tet, s.mesh.num_tets());
    EXPECT_NEAR(weight_sum(m), 1.0, 1e-9);
  }
  EXPECT_TRUE(s.markers.observed_path.empty());
  EXPECT_DOUBLE_EQ(s.time.end, 1.0);
  EXPECT_DOUBLE_EQ(s.time.output_rate, 100);
  EXPECT_DOUBLE_EQ(s.time.vtu_rate, 30);
  EXPECT_DOUBLE_EQ(s.solver.rtol, 1e-6);
  EXPECT_EQ(s.solver.max_order, 5);
  EXPECT_TRUE(s.solver.lumped_mass);
}

TEST(ScenarioExamples, FoamCylinder) {
  const Scenario s = load_scenario(example("foam-cylinder.yaml"));
  EXPECT_EQ(s.name, "foam-cylinder");
  EXPECT_GT(s.mesh.num_nodes(), 0);
  EXPECT_NEAR(s.mesh.nodes.row(2).maxCoeff(), 0.2, 1e-9);
  EXPECT_DOUBLE_EQ(s.material.density, 60);
  EXPECT_DOUBLE_EQ(s.material.elastic[0].params.at("lambda"), 1e4);
  EXPECT_DOUBLE_EQ(s.material.elastic[0].params.at("mu"), 2e4);
  ASSERT_EQ(s.material.viscous.size(), 1u);
  EXPECT_EQ(s.material.viscous[0].model, "power-law");
  EXPECT_DOUBLE_EQ(s.material.viscous[0].params.at("nu"), 12);
  EXPECT_DOUBLE_EQ(s.material.viscous[0].params.at("h"), 1);
  EXPECT_TRUE(s.static_initial);
  ASSERT_EQ(s.clamps.size(), 1u);
  ASSERT_FALSE(s.clamps[0].nodes.empty());
  for (int i : s.clamps[0].nodes) EXPECT_NEAR(s.mesh.nodes(2, i), 0.2, 1e-9);
  const auto* motion = dynamic_cast<const SinusoidMotion*>(s.clamps[0].motion.get());
  ASSERT_NE(motion, nullptr);
  // Phase -π/2: the clamp starts displaced by minus the amplitudes, at rest.
  const RigidPose p0 = motion->at(0.0);
  EXPECT_NEAR(p0.d.x(), -0.005, 1e-12);
  EXPECT_NEAR(p0.d.y(), -0.004, 1e-12);
  EXPECT_NEAR(p0.ddot.norm(), 0.0, 1e-9);
  ASSERT_EQ(s.markers.embedded.size(), 8u);
  EXPECT_EQ(s.markers.embedded[0].name, "tip");
  for (const auto& m : s.markers.embedded) {
    EXPECT_GE(m.tet, 0);
    EXPECT_NEAR(weight_sum(m), 1.0, 1e-9);
    EXPECT_LE(m.outside_distance, 0.002);
  }
  EXPECT_DOUBLE_EQ(s.time.output_rate, 180);
  EXPECT_DOUBLE_EQ(s.time.vtu_rate, 30);
}

TEST(ScenarioExamples, CsvClamp) {
  const Scenario s = load_scenario(example("csv-clamp.yaml"));
  EXPECT_EQ(s.name, "csv-clamp");
  ASSERT_EQ(s.clamps.size(), 1u);
  for (int i : s.clamps[0].nodes) EXPECT_NEAR(s.mesh.nodes(0, i), 0.0, 1e-9);
  const auto* motion = dynamic_cast<const SampledMotion*>(s.clamps[0].motion.get());
  ASSERT_NE(motion, nullptr);
  EXPECT_NEAR(motion->start_time(), 0.0, 1e-12);
  EXPECT_NEAR(motion->end_time(), 1.0, 1e-12);
  const RigidPose p0 = motion->at(0.0);
  EXPECT_NEAR((p0.R - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-9);
  EXPECT_NEAR(p0.d.norm(), 0.0, 1e-12);
  // At t = 1 the clamp is twisted by 0.08 rad about x.
  const RigidPose p1 = motion->at(1.0);
  EXPECT_NEAR(std::atan2(p1.R(2, 1), p1.R(1, 1)), 0.08, 1e-6);
  ASSERT_EQ(s.markers.embedded.size(), 2u);
  EXPECT_TRUE(s.static_initial);
}

TEST(ScenarioDefaults, MinimalFileGetsDefaults) {
  const auto dir = std::filesystem::temp_directory_path() / "kelvin_test_scenario";
  std::filesystem::create_directories(dir);
  const auto path = dir / "minimal-bar.yaml";
  std::ofstream(path) << "mesh: { generate: box, size: [0.1, 0.02, 0.02], element_size: 0.01 }\n"
                         "material: { density: 900, elastic: { model: neo-hookean } }\n"
                         "time: { end: 0.5 }\n"
                         "fit: { parameters: [elastic.mu] }\n"
                         "diagnose: {}\n";
  const Scenario s = load_scenario(path.string());
  EXPECT_EQ(s.name, "minimal-bar");
  EXPECT_GT(s.mesh.num_tets(), 0);
  EXPECT_NEAR(s.mesh.nodes.row(1).maxCoeff(), 0.02, 1e-12);
  EXPECT_EQ(s.material.elastic[0].params.size(), 2u);  // defaults filled in
  EXPECT_TRUE(s.material.viscous.empty());
  EXPECT_TRUE(s.gravity.isZero());
  EXPECT_FALSE(s.static_initial);
  EXPECT_TRUE(s.clamps.empty());
  EXPECT_TRUE(s.markers.embedded.empty());
  EXPECT_DOUBLE_EQ(s.time.end, 0.5);
  EXPECT_DOUBLE_EQ(s.time.output_rate, 100);
  EXPECT_DOUBLE_EQ(s.time.vtu_rate, 0);
  EXPECT_DOUBLE_EQ(s.solver.rtol, SolverSpec{}.rtol);
  std::filesystem::remove_all(dir);
}

TEST(ScenarioErrors, TypoKeySuggestsTheRightOne) {
  expect_refused("typo-key.yaml", {"typo-key.yaml:4:3:", "material.desnity",
                                   "unknown key 'desnity'; did you mean 'density'?"});
}

TEST(ScenarioErrors, UnknownTopLevelKeyListsAllowedKeys) {
  // `fit` is reserved (accepted); `output` is not a key and nothing is close to it.
  expect_refused("unknown-top-key.yaml", {"unknown-top-key.yaml:7:1:", "output",
                                          "unknown key 'output'", "allowed:", "material"});
}

TEST(ScenarioErrors, NegativeDensity) {
  expect_refused("negative-density.yaml", {"negative-density.yaml:3:12:", "material.density",
                                           "must be positive (got -60 kg/m³)"});
}

TEST(ScenarioErrors, PoissonRatioHalf) {
  expect_refused("poisson-half.yaml",
                 {"poisson-half.yaml:4:48:", "material.elastic.nu", "must be below 0.5"});
}

TEST(ScenarioErrors, ZeroEndTime) {
  expect_refused("zero-end.yaml", {"zero-end.yaml:6:8:", "time.end", "must be positive"});
}

TEST(ScenarioErrors, MissingRequiredKeyReportedAtParent) {
  expect_refused("missing-key.yaml",
                 {"missing-key.yaml:6:3:", "time.end", "missing required key 'end'"});
}

TEST(ScenarioErrors, EmptyClampSelection) {
  expect_refused("empty-clamp.yaml",
                 {"empty-clamp.yaml:7:13:", "clamps[0].select", "selects no node",
                  "plane z = 0.3 lies outside the mesh, which spans z in [0, 0.02]"});
}

TEST(ScenarioErrors, MarkerFarOutsideInline) {
  expect_refused("marker-outside.yaml",
                 {"marker-outside.yaml:10:26:", "markers.rest[1].at", "stray"});
}

TEST(ScenarioErrors, MarkerFarOutsideCsv) {
  expect_refused("marker-outside-csv.yaml",
                 {"marker-outside-csv.yaml:5:18:", "markers.rest", "stray"});
}

TEST(ScenarioErrors, TrackedMarkerWithoutRestPosition) {
  expect_refused("observed-unknown.yaml",
                 {"observed-unknown.yaml:9:13:", "markers.observed", "marker 'tpi'",
                  "no rest position", "did you mean 'tip'?"});
}

TEST(ScenarioErrors, MissingMeshFile) {
  expect_refused("missing-mesh-file.yaml",
                 {"missing-mesh-file.yaml:2:9:", "mesh.file", "no such file 'meshes/nowhere.msh'"});
}

TEST(ScenarioErrors, YamlSyntaxError) {
  expect_refused("syntax-error.yaml", {"syntax-error.yaml:5:", "YAML syntax error"});
}

TEST(ScenarioErrors, UnknownModel) {
  expect_refused("unknown-model.yaml",
                 {"unknown-model.yaml:4:21:", "material.elastic.model", "neo-hooken",
                  "did you mean 'neo-hookean'?", "built-in models:", "newtonian"});
}

TEST(ScenarioErrors, ViscousModelUnderElastic) {
  expect_refused("viscous-as-elastic.yaml",
                 {"viscous-as-elastic.yaml:4:21:", "material.elastic.model", "material.viscous"});
}

TEST(ScenarioErrors, ParameterOutOfRange) {
  expect_refused("param-out-of-range.yaml", {"param-out-of-range.yaml:5:43:", "material.viscous.h",
                                             "must be positive", "power-law"});
}

TEST(ScenarioErrors, ParameterBelowModelRange) {
  expect_refused("param-below-range.yaml",
                 {"param-below-range.yaml:8:13:", "material.viscous.alpha1",
                  "must be at least 0 s for model 'rayleigh' (got -0.001 s)"});
}

TEST(ScenarioErrors, NegativePoissonRatioGivesRefusedLambda) {
  expect_refused("negative-lambda.yaml", {"negative-lambda.yaml:4:48:", "material.elastic.nu",
                                          "give lambda = -178571 Pa", "must be positive"});
}

TEST(ScenarioErrors, ClampCsvShorterThanRun) {
  expect_refused("clamp-csv-short.yaml", {"clamp-csv-short.yaml:8:21:", "clamps[0].motion.file",
                                          "ends at t = 0.5 s, before time.end = 1 s"});
}

TEST(ScenarioErrors, StaticStartNeedsAClamp) {
  expect_refused("static-unclamped.yaml",
                 {"static-unclamped.yaml:6:10:", "initial", "at least one clamp"});
}

TEST(ScenarioErrors, MissingScenarioFile) {
  expect_refused("does-not-exist.yaml", {"does-not-exist.yaml", "cannot open"});
}

TEST(YamlUtil, DidYouMean) {
  EXPECT_EQ(yamlutil::levenshtein("desnity", "density"), 2u);
  EXPECT_EQ(yamlutil::levenshtein("", "abc"), 3u);
  EXPECT_EQ(yamlutil::suggestion("elastik", {"density", "elastic"}), "did you mean 'elastic'?");
  EXPECT_EQ(yamlutil::suggestion("element", {"element_size", "radius"}),
            "did you mean 'element_size'?");
  EXPECT_EQ(yamlutil::suggestion("colour", {"density", "elastic"}), "allowed: density, elastic");
}

// `mesh.refine` splits a file's or a generated mesh uniformly before anything is
// placed on it: clamps select the new nodes on their plane too, markers embed in
// the children; nonsense levels and per-element fields of the unrefined mesh are
// refused at the key.
TEST(ScenarioMesh, RefineSplitsTheMeshBeforeClampsAndMarkersArePlaced) {
  const auto dir = std::filesystem::temp_directory_path() / "kelvin_test_scenario_refine";
  std::filesystem::create_directories(dir);
  const std::string head =
      "name: bar\nmesh: { generate: box, size: [0.1, 0.02, 0.02], "
      "element_size: 0.01";
  const std::string tail =
      " }\nmaterial: { density: 900, elastic: { model: neo-hookean } }\ntime: { end: 0.1 }\n"
      "clamps: [ { name: wall, select: { plane: { axis: x, at: 0 } } } ]\n";
  const auto write = [&](const std::string& name, const std::string& text) {
    const auto p = dir / name;
    std::ofstream(p) << text;
    return p.string();
  };
  const Scenario coarse = load_scenario(write("coarse.yaml", head + tail));
  const Scenario fine = load_scenario(write("fine.yaml", head + ", refine: 1" + tail));
  EXPECT_EQ(fine.mesh.num_tets(), 8 * coarse.mesh.num_tets());
  // The clamped face: (2+1)×(2+1) nodes before, (4+1)×(4+1) after.
  EXPECT_EQ(coarse.clamps[0].nodes.size(), 9u);
  EXPECT_EQ(fine.clamps[0].nodes.size(), 25u);
  for (const auto& [text, part] :
       std::vector<std::pair<std::string, std::string>>{{", refine: 4", "4 levels: give 0 … 3"},
                                                        {", refine: -1", "-1 levels"},
                                                        {", refine: 1.5", "mesh.refine"}}) {
    try {
      load_scenario(write("bad.yaml", head + text + tail));
      ADD_FAILURE() << text << " was accepted";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("bad.yaml:2:"), std::string::npos) << msg;
      EXPECT_NE(msg.find(part), std::string::npos) << msg;
    }
  }
  std::filesystem::remove_all(dir);
}
