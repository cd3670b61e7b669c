// fitted.yaml and the `material.fields` it relies on: the written scenario rebuilds
// exactly the fitted model (global values as scalars, the rest as per-element
// fields), names its files by absolute paths, runs under `kelvin simulate`, and a
// bad fields file is refused with its file and line.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <string>
#include <vector>

#include "base/error.hpp"
#include "fit/fitted_scenario.hpp"
#include "test_support.hpp"
#include "yaml/scenario_simulation.hpp"

using namespace kelvin;
using kelvin::test::read_text;
using kelvin::test::run_kelvin;
using kelvin::test::write_text;
namespace fs = std::filesystem;

namespace {

/// A clamped bar with markers, a clamp trajectory and a further experiment, all
/// named by relative paths. `material` replaces the body of the material section
/// and `fit` that of the fit section.
std::string bar(const std::string& material, const std::string& fit) {
  return "mesh: { generate: box, size: [0.1, 0.02, 0.02], element_size: 0.01 }\n"
         "material:\n" +
         material +
         "gravity: [0, 0, -9.81]\n"
         "clamps:\n"
         "  - { name: base, select: { plane: { axis: x, at: 0 } }, motion: { file: "
         "data/clamp.csv } }\n"
         "markers: { rest: data/markers.csv, observed: data/tracks.csv }\n"
         "time: { end: 0.5 }\n" +
         (fit.empty() ? "" : "fit:\n" + fit);
}

const std::string kMaterial =
    "  density: 900\n"
    "  elastic: { model: neo-hookean, E: 3.0e4, nu: 0.3 }\n"
    "  viscous: { model: newtonian, nu: 5 }\n";

class FittedScenario : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::scratch(std::string("fitted-scenario-") +
                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_ / "in" / "data");
    write_text(dir_ / "in" / "data" / "clamp.csv",
               "t,tx,ty,tz,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n1,0,0,0,1,0,0,0\n");
    write_text(dir_ / "in" / "data" / "markers.csv",
               "name,x,y,z\ntip,0.1,0.01,0.01\nmid,0.05,0.01,0.01\n");
    write_text(dir_ / "in" / "data" / "tracks.csv",
               "t,tip_x,tip_y,tip_z\n0,0.1,0.01,0.01\n0.5,0.1,0.01,0.009\n");
    write_text(dir_ / "in" / "other.yaml", bar(kMaterial, ""));
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& text) const {
    write_text(dir_ / "in" / name, text);
    return (dir_ / "in" / name).string();
  }
  std::string abs(const std::string& relative) const {
    return fs::absolute(dir_ / "in" / relative).lexically_normal().string();
  }

  /// Loads `yaml`, moves every fitted entry away from its start (so that no
  /// value is the input's), writes fitted.yaml and returns the fitted model's
  /// quantities next to the path.
  struct Fitted {
    std::string path;
    std::vector<Eigen::MatrixXd> q;
    Eigen::VectorXd density;
  };
  Fitted fit(const std::string& yaml) const {
    const Scenario s = load_scenario(write("bar.yaml", yaml));
    auto model = build_model(s);
    const ParameterMap map(s.fit.parameters, s, *model);
    Eigen::VectorXd p = map.initial();
    for (int j = 0; j < p.size(); ++j) p[j] += 0.01 * (j % 7 + 1) / 3.0;
    map.apply(p, *model);
    Fitted f;
    f.path = write_fitted_scenario(s, map, *model, (dir_ / "out").string());
    for (const auto& t : model->terms()) f.q.push_back(t.q);
    f.density = model->density();
    return f;
  }

  /// The fitted scenario rebuilds the fitted model exactly.
  static void expect_same_model(const Fitted& f) {
    const Scenario s = load_scenario(f.path);
    const auto model = build_model(s);
    ASSERT_EQ(model->terms().size(), f.q.size());
    for (size_t t = 0; t < f.q.size(); ++t)
      for (int e = 0; e < f.q[t].cols(); ++e)
        for (int k = 0; k < f.q[t].rows(); ++k)
          ASSERT_EQ(model->terms()[t].q(k, e), f.q[t](k, e))
              << "term " << t << " param " << k << " element " << e;
    for (int e = 0; e < f.density.size(); ++e)
      ASSERT_EQ(model->density()[e], f.density[e]) << "element " << e;
  }

  /// The message of the error that loading `yaml` raises ("" if none).
  std::string refusal(const std::string& yaml) const {
    try {
      load_scenario(write("bad.yaml", yaml));
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  }

  fs::path dir_;
};

TEST_F(FittedScenario, GlobalAndBoxAndElementValuesRoundTripExactly) {
  const Fitted f = fit(bar(kMaterial,
                           "  parameters:\n"
                           "    - { target: elastic.mu, initial: 2.0e4, scope: global }\n"
                           "    - { target: density, initial: 1000, scope: { boxes: [ { min: "
                           "[0, 0, 0], max: [0.05, 0.02, 0.02] } ] } }\n"
                           "    - { target: viscous.nu, scope: per-element, lower: 1, upper: 50 }\n"
                           "  experiments: [other.yaml]\n"));
  expect_same_model(f);

  const std::string text = read_text(f.path);
  EXPECT_EQ(text.rfind("# Written by kelvin fit from " + abs("bar.yaml"), 0), 0u) << text;
  const YAML::Node y = YAML::LoadFile(f.path);
  // E and ν gave way to λ and μ: the fitted μ is a scalar, λ the one E and ν meant.
  const YAML::Node elastic = y["material"]["elastic"];
  EXPECT_FALSE(elastic["E"]);
  EXPECT_FALSE(elastic["nu"]);
  EXPECT_EQ(elastic["mu"].as<double>(), f.q[0](1, 0));
  EXPECT_DOUBLE_EQ(elastic["lambda"].as<double>(), 3.0e4 * 0.3 / (1.3 * 0.4));
  EXPECT_EQ(y["material"]["fields"].as<std::string>(), "fitted-fields.csv");
  EXPECT_EQ(read_text(dir_ / "out" / "fitted-fields.csv").substr(0, 27),
            "element,density,viscous.nu\n");
  for (const auto& p : y["fit"]["parameters"]) EXPECT_FALSE(p["initial"]);
  EXPECT_EQ(y["name"].as<std::string>(), "bar");

  // Every path is absolute and names the input's file.
  EXPECT_EQ(y["markers"]["rest"].as<std::string>(), abs("data/markers.csv"));
  EXPECT_EQ(y["markers"]["observed"].as<std::string>(), abs("data/tracks.csv"));
  EXPECT_EQ(y["clamps"][0]["motion"]["file"].as<std::string>(), abs("data/clamp.csv"));
  EXPECT_EQ(y["fit"]["experiments"][0].as<std::string>(), abs("other.yaml"));
  const Scenario s = load_scenario(f.path);
  EXPECT_EQ(s.markers.observed_path, abs("data/tracks.csv"));
  EXPECT_EQ(s.fit.experiments.at(0), abs("other.yaml"));
  EXPECT_EQ(s.fit.parameters.size(), 3u);
  EXPECT_EQ(s.material.fields.size(), 2u);
}

TEST_F(FittedScenario, InputFieldsAreCarriedOverAndOneRegionIsAScalar) {
  std::string nu = "element,viscous.nu\n";
  const int ne = load_scenario(write("plain.yaml", bar(kMaterial, ""))).mesh.num_tets();
  for (int e = 0; e < ne; ++e) nu += fmt::format("{},{:.17g}\n", e, 3 + 0.1 * e / 7);
  write("data/nu.csv", nu);
  const Fitted f = fit(bar(kMaterial + "  fields: data/nu.csv\n",
                           "  parameters:\n"
                           "    - { target: density, scope: per-region }\n"
                           "    - { target: elastic.lambda, scope: { boxes: [ { min: [0, 0, 0], "
                           "max: [0.03, 0.02, 0.02] } ] } }\n"));
  expect_same_model(f);
  const Scenario s = load_scenario(f.path);
  // A generated mesh has one region, so per-region density is one value.
  EXPECT_EQ(s.material.density, f.density[0]);
  ASSERT_EQ(s.material.fields.size(), 2u);
  EXPECT_EQ(s.material.fields[0].target, "viscous.nu");
  EXPECT_EQ(s.material.fields[1].target, "elastic.lambda");
  EXPECT_EQ(s.material.fields[0].values[ne - 1], 3 + 0.1 * (ne - 1) / 7);
}

TEST_F(FittedScenario, SimulateRunsTheFittedScenario) {
  const Fitted f = fit(bar(kMaterial,
                           "  parameters:\n"
                           "    - { target: elastic.mu, scope: global }\n"
                           "    - { target: density, scope: per-element }\n"));
  const test::CliRun r =
      run_kelvin("simulate " + f.path + " --end 0.01 -q -o " + (dir_ / "sim").string());
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_TRUE(fs::exists(dir_ / "sim" / "markers.csv")) << r.out;
}

TEST_F(FittedScenario, BadFieldsFilesAreRefusedWithFileAndLine) {
  const int ne = load_scenario(write("plain.yaml", bar(kMaterial, ""))).mesh.num_tets();
  const std::string yaml = bar(kMaterial + "  fields: f.csv\n", "");
  const std::string at = abs("bad.yaml") + ":6:11: material.fields: " + abs("f.csv");
  // Rows for the elements 0 … n−1 but `skip`, each with density 900.
  auto rows = [&](int skip = -1, const std::string& header = "element,density") {
    std::string s = header + "\n";
    for (int e = 0; e < ne; ++e)
      if (e != skip) s += fmt::format("{},900\n", e);
    return s;
  };
  struct Case {
    std::string name, csv, expected;
  };
  const std::vector<Case> cases = {
      {"gap", rows(3),
       fmt::format(":{}: element {} is listed, but element 3 has no row", ne, ne - 1)},
      {"short", rows(ne - 1),
       fmt::format(":{}: the file ends after element {}, but the mesh has {} elements", ne, ne - 2,
                   ne)},
      {"beyond", rows() + fmt::format("{},900\n", ne),
       fmt::format(":{}: element {} is beyond the mesh", ne + 2, ne)},
      {"duplicate", rows() + "7,900\n",
       fmt::format(":{}: element 7 appears twice (first on line 9)", ne + 2)},
      {"unknown target", rows(-1, "element,elastic.mue"),
       ":1: column 2: 'elastic.mue' is not a quantity of this material; did you mean "
       "'elastic.mu'?"},
      {"out of range", "element,density\n0,900\n1,-2\n",
       ":3: column 2 (density) of element 1: must be positive (got -2 kg/m³)"},
      {"model range", "element,elastic.mu\n0,0\n",
       ":2: column 2 (elastic.mu) of element 0: must be positive for model 'neo-hookean'"},
      {"not a number", "element,density\n0,9OO\n",
       ":2: column 2 (density) '9OO' is not a finite number"},
      {"columns", "element,density\n0,900,1\n", ":2: 3 columns, the header has 2"},
      {"header", "density,element\n", ":1: the header must be 'element' followed by"},
  };
  for (const auto& c : cases) {
    write("f.csv", c.csv);
    const std::string why = refusal(yaml);
    EXPECT_NE(why.find(at + c.expected), std::string::npos) << c.name << ": " << why;
  }
  write("f.csv", rows());
  EXPECT_EQ(refusal(yaml), "");
}

}  // namespace

TEST_F(FittedScenario, ObservationParametersAreListedAndTheClockOffsetStartsTheNextFit) {
  const Scenario s =
      load_scenario(write("bar.yaml", bar(kMaterial,
                                          "  parameters:\n"
                                          "    - elastic.mu\n"
                                          "    - markers.clock_offset\n"
                                          "    - { target: markers.tip.offset }\n")));
  auto model = build_model(s);
  const ParameterMap map(s.fit.parameters, s, *model, {"tip"});
  ASSERT_EQ(map.observation_blocks().size(), 2u);
  Eigen::VectorXd p = map.initial();
  const auto block = [](const ParameterMap& m, const std::string& target) {
    for (const ObservationBlock& o : m.observation_blocks())
      if (o.target == target) return o;
    throw Error("no block " + target);
  };
  const ObservationBlock clock = block(map, "markers.clock_offset");
  const ObservationBlock tip = block(map, "markers.tip.offset");
  p[clock.offset] = 0.0125;
  p.segment(tip.offset, 3) << 0.001, -0.002, 0.003;
  map.apply(p, *model);
  const std::string path = write_fitted_scenario(s, map, *model, (dir_ / "out").string(), p);

  const std::string text = read_text(path);
  EXPECT_NE(text.find("#   markers.clock_offset = 0.0125\n"), std::string::npos) << text;
  EXPECT_NE(text.find("#   markers.tip.offset = 0.001 -0.002 0.003\n"), std::string::npos) << text;
  // The next fit starts at the fitted clock offset (the string entry became a mapping);
  // the marker offsets, three numbers, start at zero again.
  const Scenario back = load_scenario(path);
  auto rebuilt = build_model(back);
  const ParameterMap again(back.fit.parameters, back, *rebuilt, {"tip"});
  const Eigen::VectorXd start = again.initial();
  EXPECT_EQ(start[block(again, "markers.clock_offset").offset], 0.0125);
  EXPECT_EQ(start.segment(block(again, "markers.tip.offset").offset, 3).norm(), 0);
  EXPECT_EQ(again.value(start, 0), map.value(p, 0));  // μ, as every fitted material value
}
