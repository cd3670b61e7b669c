// Material plugins: the example plugin loads and passes the derivative checks; a
// wrong ABI, a missing symbol, a NaN or a throw are reported, never crash.
#include <gtest/gtest.h>

#include "base/error.hpp"
#include "materials/derivative_check.hpp"
#include "materials/material.hpp"
#include "materials/plugin_loader.hpp"

using namespace kelvin;

namespace {

std::string load_error(const std::string& path, const std::string& model) {
  try {
    create_material(model, path);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

MaterialPoint point(const Mat3& F, const double* q) {
  MaterialPoint p;
  p.F = F;
  p.q = q;
  p.element = 42;
  return p;
}

}  // namespace

TEST(Plugins, ExamplePluginLoadsAndPassesDerivativeChecks) {
  auto m = create_material("yeoh", KELVIN_YEOH_PLUGIN);
  ASSERT_TRUE(m);
  EXPECT_EQ(m->name(), "yeoh");
  ASSERT_EQ(m->params().size(), 3u);
  EXPECT_EQ(m->params()[0].name, "c1");
  EXPECT_TRUE(m->params()[0].positive);
  EXPECT_TRUE(m->has_energy());
  const auto checks = check_material_derivatives(*m, {2e4, 5e3, 3e4});
  ASSERT_FALSE(checks.empty());
  for (const auto& c : checks)
    EXPECT_TRUE(c.passed()) << c.what << " at " << c.state << ": " << c.error;
}

TEST(Plugins, ExamplePluginWithoutStiffeningIsLinearElasticAtSmallStrain) {
  // c2 = 0: σ ≈ λ tr ε I + 2 μ ε with μ = 2 c1.
  auto m = create_material("yeoh", KELVIN_YEOH_PLUGIN);
  const double q[] = {2e4, 0, 3e4};
  Mat3 eps;
  eps << 1, 2, 0.5, 2, -1, 0.3, 0.5, 0.3, 0.7;
  eps *= 1e-6;
  MaterialResponse r;
  ASSERT_TRUE(m->evaluate(point(Mat3::Identity() + eps, q), kStress, r));
  const Mat3 linear = 3e4 * eps.trace() * Mat3::Identity() + 2 * (2 * 2e4) * eps;
  EXPECT_LT((r.P - linear).norm() / linear.norm(), 1e-5);
}

TEST(Plugins, WrongAbiVersionIsRefusedWithBothVersions) {
  const std::string msg = load_error(KELVIN_BAD_ABI_PLUGIN, "x");
  EXPECT_NE(msg.find("was built for kelvin plugin ABI 3.0.0"), std::string::npos) << msg;
  EXPECT_NE(msg.find("this kelvin has ABI 2.0.0"), std::string::npos) << msg;
  EXPECT_NE(msg.find(KELVIN_BAD_ABI_PLUGIN), std::string::npos) << msg;
}

TEST(Plugins, MissingSymbolIsRefusedByName) {
  const std::string msg = load_error(KELVIN_MISSING_SYMBOL_PLUGIN, "x");
  EXPECT_NE(msg.find("does not export kelvin_plugin_materials()"), std::string::npos) << msg;
}

TEST(Plugins, NotALibraryAndMissingFileAreErrors) {
  EXPECT_NE(load_error(KELVIN_TEST_DATA "/plugins/not-a-plugin.so", "x")
                .find("cannot load material plugin"),
            std::string::npos);
  EXPECT_NE(load_error("/nonexistent/libnothing.so", "x").find("/nonexistent/libnothing.so"),
            std::string::npos);
}

TEST(Plugins, UnknownModelListsWhatThePluginExports) {
  const std::string msg = load_error(KELVIN_MISBEHAVING_PLUGIN, "neo");
  EXPECT_NE(msg.find("has no model 'neo'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("nan-model, throwing-model, segfault-model"), std::string::npos) << msg;
}

TEST(Plugins, NonFiniteStressIsReportedWithElementAndState) {
  auto m = create_material("nan-model", KELVIN_MISBEHAVING_PLUGIN);
  const double q[] = {1e4};
  MaterialResponse r;
  EXPECT_TRUE(m->evaluate(point(Mat3::Identity(), q), kStress, r));
  try {
    m->evaluate(point(1.2 * Mat3::Identity(), q), kStress, r);
    FAIL() << "NaN stress was accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("element 42"), std::string::npos) << msg;
    EXPECT_NE(msg.find("non-finite value in P"), std::string::npos) << msg;
    EXPECT_NE(msg.find("F = [1.2 0 0; 0 1.2 0; 0 0 1.2]"), std::string::npos) << msg;
  }
}

TEST(Plugins, ThrowingModelIsReportedWithItsMessage) {
  auto m = create_material("throwing-model", KELVIN_MISBEHAVING_PLUGIN);
  const double q[] = {1e4};
  MaterialResponse r;
  try {
    m->evaluate(point(Mat3::Identity(), q), kStress, r);
    FAIL() << "exception was swallowed";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("table lookup out of range"), std::string::npos) << msg;
    EXPECT_NE(msg.find("element 42"), std::string::npos) << msg;
  }
}
