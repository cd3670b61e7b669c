// Per-element fits (Bächer 2008): a bar made of a soft half and a 10× stiffer half,
// driven at both ends; fitting the Lamé parameters element by element, from a
// uniform start and with a smoothness penalty, must put the stiffness jump at the
// true interface.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <iostream>
#include <sstream>

#include "fit/fit_loop.hpp"
#include "test_support.hpp"

namespace kelvin {
namespace {

using test::fs::path;

// An 80 × 20 × 20 mm box of 10 mm cells: 8 layers of cells along x, 8·2·2·6 = 192 tets.
constexpr double kLength = 0.08, kCell = 0.01, kInterface = 0.04;
constexpr int kLayers = 8;
// Soft half x < 40 mm, stiff half x > 40 mm; λ = 2μ in both (Poisson ratio 1/3).
constexpr double kSoftMu = 1.0e5, kStiffMu = 1.0e6;
// Smoothness weight γ. Φ starts at ~8e-7 m²s; the truth's roughness Σ (ln μ_a − ln μ_b)²
// over face neighbours is ~42 per field (8 faces across the interface, each (ln 10)²),
// so γ = 1e-11 charges the true jump ~1e-3 of the starting misfit: enough to tie the
// elements of a layer together, too little to smear the jump over several layers.
constexpr double kGamma = 1e-11;

/// The bar clamped at both ends: the end x = 0 moves along y at 17 Hz and along z at
/// 11 Hz, the end x = 80 mm along x (stretching the bar) at 13 Hz, all starting at
/// rest, from static equilibrium under gravity, 0.1 s. Markers sit on every surface
/// node between the clamps (7 stations × 8 nodes). `mu` is the uniform shear modulus
/// (λ = 2μ), replaced by the file `fields` when given.
std::string bar(double mu, const std::string& fields, const std::string& tail = "") {
  std::string markers = "markers:\n  rest:\n";
  for (int i = 1; i < kLayers; ++i)
    for (int j = 0; j <= 2; ++j)
      for (int k = 0; k <= 2; ++k) {
        if (j == 1 && k == 1) continue;  // the node on the axis is inside the bar
        markers += fmt::format("    - {{ name: m{}{}{}, at: [{}, {}, {}] }}\n", i, j, k, i * kCell,
                               j * kCell, k * kCell);
      }
  return fmt::format(R"(
name: two-material-bar
mesh: {{ generate: box, lo: [0, 0, 0], hi: [{}, 0.02, 0.02], element_size: {} }}
material:
  density: 1100
  elastic: {{ model: neo-hookean, lambda: {}, mu: {} }}
  viscous: {{ model: newtonian, nu: 50 }}
{}gravity: [0, 0, -9.81]
initial: static
clamps:
  - name: left
    select: {{ plane: {{ axis: x, at: 0 }} }}
    motion:
      sinusoids:
        translation:
          - {{ amplitude: 0.003, frequency: 17, phase: -1.5707963267948966, direction: [0, 1, 0] }}
          - {{ amplitude: 0.002, frequency: 11, phase: -1.5707963267948966, direction: [0, 0, 1] }}
  - name: right
    select: {{ plane: {{ axis: x, at: {} }} }}
    motion:
      sinusoids:
        translation:
          - {{ amplitude: 0.002, frequency: 13, phase: -1.5707963267948966, direction: [1, 0, 0] }}
time: {{ end: 0.1, output_rate: 500 }}
solver: {{ rtol: 1.0e-6, atol: 1.0e-10 }}
)",
                     kLength, kCell, 2 * mu, mu, fields.empty() ? "" : "  fields: " + fields + "\n",
                     kLength) +
         markers + tail;
}

Eigen::Vector3d centroid(const Mesh& mesh, int e) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a) c += mesh.nodes.col(mesh.tets(a, e));
  return c / 4;
}

/// Geometric mean of block `block`'s fitted values over each layer of elements along x.
std::vector<double> layer_means(const ParameterMap& map, const Eigen::VectorXd& p, int block,
                                const std::vector<int>& layer) {
  std::vector<double> log_sum(kLayers, 0.0);
  std::vector<int> count(kLayers, 0);
  const ParameterBlock& b = map.blocks()[block];
  for (int e = 0; e < static_cast<int>(layer.size()); ++e) {
    log_sum[layer[e]] += std::log(map.value(p, b.offset + b.entry[e]));
    ++count[layer[e]];
  }
  std::vector<double> mean(kLayers);
  for (int l = 0; l < kLayers; ++l) mean[l] = std::exp(log_sum[l] / count[l]);
  return mean;
}

std::string profile(const std::vector<double>& v) {
  std::string s;
  for (double x : v) s += fmt::format("{}{:.3g}", s.empty() ? "" : " ", x);
  return s;
}

// Noise-free and in the model class. μ and λ are both fitted per element from a
// uniform start (the geometric mean of the truths), so nothing in the fit knows
// where the interface is. Without smoothness the fit finds the jump too; γ keeps
// each layer's elements together.
TEST(FitFields, PerElementStiffnessJumpLandsAtTheInterface) {
  const auto clock = std::chrono::steady_clock::now();
  const path dir = test::scratch("fit-fields");
  test::write_text(dir / "mesh.yaml", bar(kSoftMu, ""));
  const Mesh mesh = load_scenario((dir / "mesh.yaml").string()).mesh;
  const int ne = mesh.num_tets();
  ASSERT_EQ(ne, 192);
  std::vector<int> layer(ne);
  std::ostringstream truth_fields;
  truth_fields << "element,elastic.lambda,elastic.mu\n";
  for (int e = 0; e < ne; ++e) {
    const double x = centroid(mesh, e).x();
    layer[e] = static_cast<int>(std::floor(x / kCell));
    const double mu = x < kInterface ? kSoftMu : kStiffMu;
    truth_fields << e << "," << 2 * mu << "," << mu << "\n";
  }
  test::write_text(dir / "truth-fields.csv", truth_fields.str());
  const std::string tracks = test::simulate_tracks(dir, "truth", bar(kSoftMu, "truth-fields.csv"));

  const double start = std::sqrt(kSoftMu * kStiffMu);
  test::write_text(dir / "fit.yaml",
                   bar(start, "",
                       fmt::format("  observed: {}\nfit:\n  parameters:\n"
                                   "    - {{ target: elastic.mu, scope: per-element }}\n"
                                   "    - {{ target: elastic.lambda, scope: per-element }}\n",
                                   tracks)));
  const Scenario scenario = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(scenario, scenario.fit.parameters);
  const ParameterMap& map = problem.map();
  ASSERT_EQ(map.size(), 2 * ne);
  ASSERT_TRUE(map.is_log(0) && map.is_log(ne));
  FitOptions o;
  o.algorithm = "lbfgs";
  o.gradient.method = GradientMethod::kAdjoint;
  o.max_evaluations = 120;
  o.ftol_rel = 1e-12;
  o.xtol_rel = 1e-10;
  o.smoothness = kGamma;
  const FitOutcome out = run_fit(problem, map.initial(), o);
  ASSERT_GT(out.best.evaluation, 0) << out.stop_reason;

  const std::vector<double> mu = layer_means(map, out.p, 0, layer);
  const std::vector<double> lambda = layer_means(map, out.p, 1, layer);
  int jump = 0;  // the largest |Δ ln μ| between consecutive layers: layers jump, jump + 1
  for (int l = 1; l + 1 < kLayers; ++l)
    if (std::abs(std::log(mu[l + 1] / mu[l])) > std::abs(std::log(mu[jump + 1] / mu[jump])))
      jump = l;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - clock).count();
  std::cout << fmt::format(
      "fitted per layer, x = 0-10 ... 70-80 mm (truth mu {:g} | {:g} Pa, lambda = 2 mu):\n"
      "  mu     {}\n  lambda {}\nlargest mu jump between layers {} and {}; rms {:.3g} -> {:.3g} m "
      "(penalty {:.2g}, misfit {:.2g}) after {} evaluations ({}); {:.0f} s\n",
      kSoftMu, kStiffMu, profile(mu), profile(lambda), jump, jump + 1, out.history.front().rms,
      out.best.rms, out.best.penalty, out.best.misfit, out.evaluations, out.stop_reason, seconds);
  RecordProperty("layer_mu", profile(mu));
  RecordProperty("layer_lambda", profile(lambda));

  EXPECT_LE(std::abs(jump - 3), 1) << profile(mu);  // the interface lies between layers 3 and 4
  EXPECT_GE(mu[kLayers - 1] / mu[0], 3.0) << profile(mu);
  EXPECT_LT(out.best.rms, out.history.front().rms / 10);
}

}  // namespace
}  // namespace kelvin
