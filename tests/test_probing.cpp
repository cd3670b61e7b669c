// The inverses of static probing (Bächer 2008, §5.2 and §5.3) on synthetic probes
// of a foam block that kelvin's static solver makes. Force-based: exact recovery of
// a warped-stiffness (corotational) truth, the small-strain agreement with a
// neo-Hookean truth and the error a single linear set leaves at large strain, a
// stiff inclusion found where it is by the per-element fit with the L-curve.
// Displacement-based: recovery from surface markers alone, and the comparison of
// the two with marker noise.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>

#include "base/error.hpp"
#include "engine/fem_model.hpp"
#include "engine/mesh.hpp"
#include "engine/selection.hpp"
#include "engine/static_solver.hpp"
#include "probing/displacement_inverse.hpp"
#include "probing/force_inverse.hpp"
#include "probing/parameter_sets.hpp"
#include "test_support.hpp"

using namespace kelvin;

namespace {

constexpr double kLambda = 2e4, kMu = 1e4;  // Pa: a soft foam (E 26.7 kPa, ν 0.33)

/// A 40 × 40 × 20 mm block on a rigid table (its base clamped).
Mesh block() {
  return generate_box({0, 0, 0}, {0.04, 0.04, 0.02}, 0.005);
}

struct Probe {
  Eigen::Vector2d at;     // (x, y) on the top face (m)
  Eigen::Vector3d force;  // N, total over the nodes within 6 mm
};

std::unique_ptr<FemModel> probed_model(const Mesh& mesh, const std::string& law,
                                       const Eigen::MatrixXd& q, const Probe& probe) {
  NodeSelection base;
  base.axis = 2, base.at = 0;
  std::vector<ClampBinding> clamps{
      {"table", select_nodes(mesh, base), std::make_shared<FixedMotion>()}};
  NodeLoad load{"probe", {}, probe.force, 0};
  for (int a = 0; a < mesh.num_nodes(); ++a) {
    const Eigen::Vector3d X = mesh.nodes.col(a);
    if (std::abs(X.z() - 0.02) < 1e-9 && (X.head<2>() - probe.at).norm() <= 0.006)
      load.nodes.push_back(a);
  }
  std::vector<MaterialTerm> terms{{create_builtin_material(law), q, {}}};
  return std::make_unique<FemModel>(
      mesh, std::move(terms), Eigen::VectorXd::Constant(mesh.num_tets(), 60.0),
      Eigen::Vector3d::Zero(), clamps, true, std::vector<NodeLoad>{load});
}

/// The equilibrium positions of every node under the model's loads.
Eigen::Matrix3Xd equilibrium(const FemModel& model) {
  Eigen::VectorXd x = rigid_initial_guess(model, 0);
  const StaticResult r = solve_static(model, 0, x);
  EXPECT_TRUE(r.converged) << r.message;
  Eigen::Matrix3Xd full, v;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(x.size());
  model.expand(0, x.data(), zero.data(), full, v);
  return full;
}

Eigen::MatrixXd uniform(const Mesh& mesh, double lambda, double mu) {
  return Eigen::Vector2d(lambda, mu).replicate(1, mesh.num_tets());
}

/// The largest nodal displacement over the block's height.
double peak_strain(const Mesh& mesh, const Eigen::Matrix3Xd& x) {
  return (x - mesh.nodes).colwise().norm().maxCoeff() / 0.02;
}

}  // namespace

TEST(ForceInverse, RecoversAWarpedStiffnessBlockExactly) {
  const Mesh mesh = block();
  const auto model = probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu),
                                  {{0.02, 0.02}, {0.1, 0.05, -0.8}});
  const Eigen::Matrix3Xd x = equilibrium(*model);
  ASSERT_GT(peak_strain(mesh, x), 0.1);  // large rotations: the warping matters

  // The inverse starts from other values; linearity makes them irrelevant.
  const auto start =
      probed_model(mesh, "corotational", uniform(mesh, 1, 1), {{0.02, 0.02}, {0.1, 0.05, -0.8}});
  ForceInverseOptions o;
  o.grouping = ElementGrouping::kGlobal;
  const ForceInverseResult r = force_based_inverse({{start.get(), x}}, o);
  ASSERT_EQ(r.parameters, (std::vector<std::string>{"lambda", "mu"}));
  EXPECT_NEAR(r.q[0](0, 0), kLambda, 1e-6 * kLambda);
  EXPECT_NEAR(r.q[0](1, 0), kMu, 1e-6 * kMu);
  EXPECT_LT(r.relative_residual, 1e-7);
  EXPECT_NEAR(youngs_modulus(r.q[0](0, 0), r.q[0](1, 0)),
              kMu * (3 * kLambda + 2 * kMu) / (kLambda + kMu), 1);
}

TEST(ForceInverse, AgreesWithANeoHookeanTruthAtSmallStrainAndLeavesAnErrorAtLarge) {
  const Mesh mesh = block();
  double residual[2];
  int i = 0;
  for (double load : {0.008, 0.8}) {
    const Probe probe{{0.02, 0.02}, {0, 0, -load}};
    const auto truth = probed_model(mesh, "neo-hookean", uniform(mesh, kLambda, kMu), probe);
    const auto model = probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu), probe);
    ForceInverseOptions o;
    o.grouping = ElementGrouping::kGlobal;
    const ForceInverseResult r = force_based_inverse({{model.get(), equilibrium(*truth)}}, o);
    residual[i++] = r.relative_residual;
    if (load < 0.1) {  // both laws have the Lamé moduli λ, μ at F = I
      EXPECT_NEAR(r.q[0](1, 0), kMu, 0.01 * kMu);
      EXPECT_NEAR(r.q[0](0, 0), kLambda, 0.03 * kLambda);
    }
  }
  // The laws differ at second order in the strain: the misfit a single linear set
  // leaves grows with the indentation (100× the load: more than 10× the residual).
  EXPECT_GT(residual[1], 10 * residual[0]);
}

TEST(ForceInverse, PerElementFitPutsAStiffInclusionWhereItIsAndNoiseBiasesItLow) {
  const Mesh mesh = block();
  // 5× stiffer in a 10 mm cube under the top centre.
  const Eigen::Vector3d lo(0.015, 0.015, 0.005), hi(0.025, 0.025, 0.015);
  Eigen::MatrixXd q = uniform(mesh, kLambda, kMu);
  std::vector<bool> inside(mesh.num_tets());
  for (int e = 0; e < mesh.num_tets(); ++e) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) c += mesh.nodes.col(mesh.tets(a, e)) / 4;
    inside[e] = (c.array() > lo.array()).all() && (c.array() < hi.array()).all();
    if (inside[e]) q.col(e) *= 5;
  }
  // Five probes, 0.3 N each, around the top centre.
  std::vector<std::unique_ptr<FemModel>> models;
  std::vector<Eigen::Matrix3Xd> truths;
  for (const Eigen::Vector2d& at :
       {Eigen::Vector2d(0.02, 0.02), Eigen::Vector2d(0.012, 0.02), Eigen::Vector2d(0.028, 0.02),
        Eigen::Vector2d(0.02, 0.012), Eigen::Vector2d(0.02, 0.028)}) {
    const Probe probe{at, {0.05, -0.05, -0.3}};
    truths.push_back(equilibrium(*probed_model(mesh, "corotational", q, probe)));
    models.push_back(probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu), probe));
  }
  // μ averaged inside and outside the inclusion, with noise σ on the free nodes.
  auto fit = [&](double sigma) {
    std::mt19937 rng(7);
    std::normal_distribution<double> noise(0, sigma);
    std::vector<StaticState> states;
    for (size_t m = 0; m < truths.size(); ++m) {
      Eigen::Matrix3Xd x = truths[m];
      for (int a = 0; a < x.cols(); ++a)
        if (mesh.nodes(2, a) > 0)
          for (int i = 0; i < 3; ++i) x(i, a) += noise(rng);
      states.push_back({models[m].get(), x});
    }
    ForceInverseOptions o;
    for (int i = -4; i <= 0; ++i) o.lcurve.push_back(std::pow(10.0, i));
    const ForceInverseResult r = force_based_inverse(states, o);
    double in = 0, out = 0;
    int n_in = 0;
    for (int e = 0; e < mesh.num_tets(); ++e) (inside[e] ? (++n_in, in) : out) += r.q[0](1, e);
    return std::tuple(in / n_in, out / (mesh.num_tets() - n_in), r);
  };
  {
    const auto [in, out, r] = fit(1e-6);
    // The L-curve's corner is inside the grid (neither end).
    EXPECT_GT(r.gamma_space, r.lcurve.front().gamma);
    EXPECT_LT(r.gamma_space, r.lcurve.back().gamma);
    EXPECT_GT(in, 2 * out) << "μ inside " << in << ", outside " << out;
    EXPECT_NEAR(out, kMu, 0.3 * kMu);
  }
  {
    // Noise in the measured positions enters A (errors in the variables): it
    // inflates the apparent strains, and the moduli come out low. At 10 µm the
    // inclusion still stands out, but both levels drop by half or more.
    const auto [in, out, r] = fit(1e-5);
    EXPECT_GT(in, 2 * out) << "μ inside " << in << ", outside " << out;
    EXPECT_LT(out, 0.6 * kMu);
    EXPECT_LT(in, 0.6 * 5 * kMu);
  }
}

TEST(ForceInverse, OneSetPerMeasurementRecoversEachProbesOwnModulus) {
  const Mesh mesh = block();
  std::vector<std::unique_ptr<FemModel>> models;
  std::vector<StaticState> states;
  const double mus[] = {kMu, 2 * kMu};  // e.g. a material that stiffens between probes
  for (double mu : mus) {
    const Probe probe{{0.02, 0.02}, {0, 0, -0.3}};
    const auto truth = probed_model(mesh, "corotational", uniform(mesh, kLambda, mu), probe);
    models.push_back(probed_model(mesh, "corotational", uniform(mesh, 1, 1), probe));
    states.push_back({models.back().get(), equilibrium(*truth)});
  }
  ForceInverseOptions o;
  o.grouping = ElementGrouping::kGlobal;
  o.per_measurement = true;
  o.gamma_measurement = 0;
  const ForceInverseResult r = force_based_inverse(states, o);
  ASSERT_EQ(r.q.size(), 2u);
  for (int m = 0; m < 2; ++m) EXPECT_NEAR(r.q[m](1, 0), mus[m], 1e-6 * mus[m]);

  // As blendable sets: each with the strain at its measured positions, the softer
  // one strained more; the smoothness across measurements pulls them together.
  o.per_measurement = false;
  const auto sets = force_parameter_sets(states, {"soft", "stiff"}, o);
  ASSERT_EQ(sets.size(), 2u);
  for (int m = 0; m < 2; ++m) {
    EXPECT_NEAR(sets[m].q(1, 0), mus[m], 1e-6 * mus[m]);
    EXPECT_LT((sets[m].strain - element_strains(mesh, states[m].x)).norm(), 1e-15);
  }
  EXPECT_GT(strain_level(mesh, sets[0].strain), 1.5 * strain_level(mesh, sets[1].strain));
  o.gamma_measurement = 10;
  const auto tied = force_parameter_sets(states, {"soft", "stiff"}, o);
  EXPECT_LT(tied[1].q(1, 0) / tied[0].q(1, 0), 1.5);
}

TEST(ForceInverse, ALawNotLinearInItsParametersIsRefusedWithTheElement) {
  const Mesh mesh = block();
  // The fibre term is linear in its stiffness k but not in its direction's angles.
  const Probe probe{{0.02, 0.02}, {0, 0, -0.3}};
  const auto truth = probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu), probe);
  const Eigen::Matrix3Xd x = equilibrium(*truth);
  std::unique_ptr<Material> law = create_builtin_material("fibre");
  ASSERT_TRUE(law);
  Eigen::VectorXd defaults(law->params().size());
  for (size_t k = 0; k < law->params().size(); ++k) defaults[k] = law->params()[k].default_value;
  defaults[0] = 1e4, defaults[1] = 0.5;
  std::vector<MaterialTerm> terms{{std::move(law), defaults.replicate(1, mesh.num_tets()), {}}};
  const FemModel model(mesh, std::move(terms), Eigen::VectorXd::Constant(mesh.num_tets(), 60.0),
                       Eigen::Vector3d::Zero(), truth->clamps(), true);
  try {
    force_based_inverse({{&model, x}});
    FAIL() << "accepted a law not linear in its parameters";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not linear in its parameters"), std::string::npos)
        << e.what();
  }
}

namespace {

/// Markers at the given nodes (weight 1 on the node), observed at x.
ObservedProbe node_markers(FemModel& model, const std::vector<int>& nodes,
                           const Eigen::Matrix3Xd& x) {
  ObservedProbe p;
  p.model = &model;
  const Mesh& mesh = model.mesh();
  for (int a : nodes) {
    MarkerEmbedding m;
    m.name = std::to_string(a);
    for (int e = 0; e < mesh.num_tets() && m.tet < 0; ++e)
      for (int k = 0; k < 4; ++k)
        if (mesh.tets(k, e) == a) m.tet = e, m.weights[k] = 1;
    p.markers.push_back(m);
  }
  p.observed.resize(3, nodes.size());
  for (size_t j = 0; j < nodes.size(); ++j) p.observed.col(j) = x.col(nodes[j]);
  return p;
}

std::vector<int> nodes_where(const Mesh& mesh, bool (*keep)(const Eigen::Vector3d&)) {
  std::vector<int> ids;
  for (int a = 0; a < mesh.num_nodes(); ++a)
    if (keep(mesh.nodes.col(a))) ids.push_back(a);
  return ids;
}

const std::vector<Probe> kThreeProbes{{{0.02, 0.02}, {0.05, 0, -0.3}},
                                      {{0.012, 0.028}, {0, 0.05, -0.3}},
                                      {{0.028, 0.012}, {-0.05, 0, -0.3}}};

}  // namespace

TEST(DisplacementInverse, RecoversTheBlockFromTopSurfaceMarkersAlone) {
  const Mesh mesh = block();
  const auto top = nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.z() > 0.0199; });
  std::vector<std::unique_ptr<FemModel>> models;
  std::vector<ObservedProbe> probes;
  for (const Probe& probe : kThreeProbes) {
    const Eigen::Matrix3Xd x =
        equilibrium(*probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu), probe));
    // The fit starts with λ 2× and μ 0.5× off.
    models.push_back(
        probed_model(mesh, "corotational", uniform(mesh, 2 * kLambda, 0.5 * kMu), probe));
    probes.push_back(node_markers(*models.back(), top, x));
  }
  const DisplacementInverseResult r = displacement_based_inverse(probes);
  EXPECT_NEAR(r.q(0, 0), kLambda, 1e-4 * kLambda) << r.stop << " after " << r.evaluations;
  EXPECT_NEAR(r.q(1, 0), kMu, 1e-4 * kMu) << r.stop;
  EXPECT_LT(r.rms, 1e-8);
}

TEST(ProbingInverses, WithMarkerNoiseTheDisplacementBasedEstimateIsCloserToTheTruth) {
  // Two regions, the 10 mm cube under the top centre 3× stiffer; both inverses fit
  // one (λ, μ) per region from the same noisy positions of every unclamped node.
  Mesh mesh = block();
  Eigen::MatrixXd q = uniform(mesh, kLambda, kMu);
  for (int e = 0; e < mesh.num_tets(); ++e) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) c += mesh.nodes.col(mesh.tets(a, e)) / 4;
    const bool inside = (c.array() > Eigen::Array3d(0.015, 0.015, 0.005)).all() &&
                        (c.array() < Eigen::Array3d(0.025, 0.025, 0.015)).all();
    mesh.region[e] = inside;
    if (inside) q.col(e) *= 3;
  }
  const auto free = nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.z() > 0; });
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0, 2e-4);  // 0.2 mm
  std::vector<std::unique_ptr<FemModel>> models;
  std::vector<StaticState> states;
  std::vector<ObservedProbe> probes;
  for (const Probe& probe : kThreeProbes) {
    Eigen::Matrix3Xd x = equilibrium(*probed_model(mesh, "corotational", q, probe));
    for (int a : free) x.col(a) += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    models.push_back(probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu), probe));
    states.push_back({models.back().get(), x});
    probes.push_back(node_markers(*models.back(), free, x));
  }
  ForceInverseOptions fo;
  fo.grouping = ElementGrouping::kRegion;
  const ForceInverseResult force = force_based_inverse(states, fo);
  DisplacementInverseOptions dopt;
  dopt.grouping = ElementGrouping::kRegion;
  const DisplacementInverseResult disp = displacement_based_inverse(probes, dopt);
  // μ of the matrix (region 0) and of the inclusion (region 1): an element of each.
  // Noise in A makes the force-based moduli collapse (to below 1 % of the truth
  // here); the displacement-based fit keeps the noise in its residual: the matrix
  // within 10 %, the buried inclusion stiffer than it but poorly determined (+76 %).
  int e_out = 0, e_in = 0;
  while (mesh.region[e_in] == 0) ++e_in;
  const double truth[2] = {kMu, 3 * kMu};
  for (int r = 0; r < 2; ++r) {
    const int e = r ? e_in : e_out;
    const double err_force = std::abs(force.q[0](1, e) / truth[r] - 1);
    const double err_disp = std::abs(disp.q(1, e) / truth[r] - 1);
    EXPECT_LT(err_disp, err_force) << "region " << r << ": force-based μ " << force.q[0](1, e)
                                   << ", displacement-based " << disp.q(1, e);
    EXPECT_GT(err_force, 0.5) << "region " << r << ": " << force.q[0](1, e);
  }
  EXPECT_NEAR(disp.q(1, e_out), kMu, 0.1 * kMu) << disp.stop;
  EXPECT_GT(disp.q(1, e_in), 1.5 * disp.q(1, e_out));
  // The residual is the noise: 0.2 mm per coordinate.
  EXPECT_NEAR(disp.rms, 2e-4, 2e-5);
}

TEST(Blending, PerDepthSetsPredictAHeldOutDepthBetterThanOneSet) {
  // A neo-Hookean block pressed at its centre ever deeper: a warped-linear set fitted
  // to one depth is right for that depth only (the foam stiffens in compression).
  // Leave-one-out over the depths: the sets of the other depths, blended by the
  // strain level, against one set fitted to all of them.
  const Mesh mesh = generate_box({0, 0, 0}, {0.04, 0.04, 0.02}, 0.01);
  const auto top = nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.z() > 0.0199; });
  const std::vector<double> forces{0.4, 0.8, 1.2, 1.6, 2.0};
  std::vector<std::unique_ptr<FemModel>> models;
  std::vector<ObservedProbe> probes;
  std::vector<std::string> names;
  for (double f : forces) {
    const Probe probe{{0.02, 0.02}, {0, 0, -f}};
    const Eigen::Matrix3Xd x =
        equilibrium(*probed_model(mesh, "neo-hookean", uniform(mesh, kLambda, kMu), probe));
    models.push_back(probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu), probe));
    probes.push_back(node_markers(*models.back(), top, x));
    char name[16];
    std::snprintf(name, sizeof name, "%.1f N", f);
    names.push_back(name);
    std::printf("%s: peak displacement %.2f mm\n", names.back().c_str(),
                1e3 * (x - mesh.nodes).colwise().norm().maxCoeff());
  }
  DisplacementInverseOptions fit;
  fit.relative_tolerance = 1e-8;
  BlendOptions global, local;
  local.metric = BlendMetric::kLocal;
  const auto folds = cross_validate_blending(probes, names, fit, {global, local});
  // Measured: one set 0.0155, 0.0233, 0.0221, 0.0080, 0.0470 mm; blended by the
  // strain level 0.0055, 0.0030, 0.0040, 0.0072, 0.0364; by the local metric 0.0053,
  // 0.0025, 0.0036, 0.0060, 0.0335. Blending wins every fold, the two ends (where it
  // extrapolates to the nearest set) included.
  double single = 0, blended[2] = {0, 0};
  for (const auto& f : folds) {
    std::printf("%s held out: one set %.4f mm, blended %.4f mm (global), %.4f mm (local)\n",
                f.held_out.c_str(), 1e3 * f.single_rms, 1e3 * f.blended[0].rms,
                1e3 * f.blended[1].rms);
    single += f.single_rms * f.single_rms;
    for (int b = 0; b < 2; ++b) {
      EXPECT_TRUE(f.blended[b].converged) << f.held_out << " blend " << b;
      EXPECT_LT(f.blended[b].rms, f.single_rms) << f.held_out << " blend " << b;
      blended[b] += f.blended[b].rms * f.blended[b].rms;
    }
  }
  // Over the folds, blending leaves well under three quarters of one set's error.
  for (int b = 0; b < 2; ++b) EXPECT_LT(std::sqrt(blended[b] / single), 0.75) << "blend " << b;
}

TEST(ProbeFitCli, TheBundledExampleFitsTheFoamToWithinItsWarpedLinearBias) {
  const auto out = test::scratch("probe-fit");
  const test::CliRun r = test::run_kelvin(
      "probe-fit " KELVIN_SOURCE_DIR "/yaml/examples/probe-foam-block.yaml -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  double lambda = 0, mu = 0, rms = 0;
  const auto fitted = r.out.find("fitted: lambda");
  ASSERT_NE(fitted, std::string::npos) << r.out;
  ASSERT_EQ(std::sscanf(r.out.c_str() + fitted, "fitted: lambda %lf mu %lf", &lambda, &mu), 2);
  const auto at = r.out.find("marker rms");
  ASSERT_EQ(std::sscanf(r.out.c_str() + at, "marker rms %lf", &rms), 1) << r.out;
  // The truth is neo-Hookean (λ 20 kPa, μ 10 kPa) pressed 15 % deep: the warped-linear
  // law reads it somewhat stiffer, and the markers are left with their 0.05 mm noise.
  EXPECT_GT(mu, 1.0 * kMu);
  EXPECT_LT(mu, 1.2 * kMu);
  EXPECT_GT(lambda, 0.9 * kLambda);
  EXPECT_LT(lambda, 1.3 * kLambda);
  EXPECT_NEAR(rms, 0.05, 0.005);
  const std::string fields = test::read_text(out / "fitted-fields.csv");
  EXPECT_EQ(fields.rfind("element,elastic.lambda,elastic.mu\n", 0), 0u);
  EXPECT_EQ(std::count(fields.begin(), fields.end(), '\n'), 1 + 1536);
}

TEST(ProbeFitCli, BadProbingEntriesAreNamedWithTheirPlace) {
  const auto dir = test::scratch("probe-bad");
  test::write_text(dir / "markers.csv", "name,x,y,z\ntop,0.02,0.02,0.02\n");
  test::write_text(dir / "seen.csv", "name,x,y,z\ntpo,0.02,0.02,0.019\n");
  auto scenario = [&](const std::string& probing) {
    test::write_text(dir / "s.yaml",
                     "mesh: { generate: box, lo: [0, 0, 0], hi: [0.04, 0.04, 0.02], "
                     "element_size: 0.01 }\n"
                     "material: { density: 60, elastic: { model: corotational, lambda: 2e4, mu: "
                     "1e4 } }\n"
                     "clamps: [{ name: table, select: { plane: { axis: z, at: 0 } } }]\n"
                     "markers: { rest: markers.csv }\n" +
                         probing);
    return test::run_kelvin("probe-fit " + (dir / "s.yaml").string() + " -o " +
                            (dir / "out").string());
  };
  const std::string load =
      "loads: [{ name: p, select: { box: { lo: [0.01, 0.01, 0.019], hi: [0.03, 0.03, 0.021] } }, "
      "force: [0, 0, -1] }]";
  test::CliRun r =
      scenario("probing:\n  measurements:\n    - { name: a, " + load + ", observed: seen.csv }\n");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("s.yaml:7:"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("probing.measurements[0].observed"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("marker 'tpo' is not one of markers.rest"), std::string::npos) << r.out;
  r = scenario("probing:\n  method: forces\n  measurements:\n    - { name: a, " + load + " }\n");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("s.yaml:6:11: probing.method"), std::string::npos) << r.out;
  r = scenario("probing:\n  measurements:\n    - { name: a, " + load + " }\n");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("measurement 'a' has no observed positions"), std::string::npos) << r.out;
}

TEST(ProbeCli, SimulatesTheExamplesMeasurementsToWithinTheirNoise) {
  // The example's observed files are `kelvin probe` of its truth plus 0.05 mm of noise.
  const auto out = test::scratch("probe-sim");
  const std::string dir = KELVIN_SOURCE_DIR "/yaml/examples/probe-foam-block/";
  const test::CliRun r = test::run_kelvin("probe " + dir + "truth.yaml -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  for (const char* name : {"centre", "left", "corner"}) {
    const MarkerRest sim = read_marker_rest((out / (std::string(name) + ".csv")).string());
    const MarkerRest seen = read_marker_rest(dir + name + ".csv");
    ASSERT_EQ(sim.names, seen.names);
    ASSERT_EQ(sim.names.size(), 81u);
    const double rms = std::sqrt((sim.positions - seen.positions).squaredNorm() / (3.0 * 81));
    EXPECT_NEAR(rms, 5e-5, 1e-5) << name;
    // And the probe pressed it: the largest displacement is millimetres.
    const MarkerRest rest = read_marker_rest(dir + "markers.csv");
    EXPECT_GT((sim.positions - rest.positions).colwise().norm().maxCoeff(), 2e-3) << name;
  }
}

TEST(ProbeCli, BlendsTheSetsProbeFitWroteAndEachMeasurementTakesItsOwn) {
  // Three depths of the depths example on a coarse block: probe-fit --sets writes one
  // set per depth, probe --blend simulates each depth with the blend, and a depth's
  // own set carries most of its weight.
  const auto dir = test::scratch("probe-blend");
  const std::string data = KELVIN_SOURCE_DIR "/yaml/examples/";
  std::string probing = "probing:\n  measurements:\n";
  const char* const depths[3] = {"0.5", "1.5", "2.5"};
  for (const char* f : depths)
    probing += fmt::format(
        "    - {{ name: c{0}, loads: [{{ name: p, select: {{ box: {{ lo: [0.014, 0.014, 0.0199], "
        "hi: [0.026, 0.026, 0.0201] }} }}, force: [0, 0, -{0}] }}], observed: "
        "{1}probe-foam-depths/centre-{0}N.csv }}\n",
        f, data);
  test::write_text(dir / "s.yaml",
                   "mesh: { generate: box, lo: [0, 0, 0], hi: [0.04, 0.04, 0.02], "
                   "element_size: 0.01 }\n"
                   "material: { density: 60, elastic: { model: corotational, lambda: 2e4, mu: "
                   "1e4 } }\n"
                   "clamps: [{ name: table, select: { plane: { axis: z, at: 0 } } }]\n"
                   "markers: { rest: " +
                       data + "probe-foam-block/markers.csv }\n" + probing);
  const std::string s = (dir / "s.yaml").string();
  test::CliRun r = test::run_kelvin("probe-fit " + s + " -o " + (dir / "fit").string() + " --sets");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  for (const char* f : depths) {
    const std::string set = test::read_text(dir / "fit" / "sets" / fmt::format("c{}.csv", f));
    EXPECT_EQ(set.rfind("element,elastic.lambda,elastic.mu,strain.E11,", 0), 0u) << set;
    EXPECT_EQ(std::count(set.begin(), set.end(), '\n'), 1 + 192);
  }
  r = test::run_kelvin("probe " + s + " -o " + (dir / "sim").string() + " --blend " +
                       (dir / "fit").string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("blending 3 parameter sets (c0.5, c1.5, c2.5) by the global strain metric"),
            std::string::npos)
      << r.out;
  for (int k = 0; k < 3; ++k) {
    const auto at = r.out.find(fmt::format("c{}: mean weights", depths[k]));
    ASSERT_NE(at, std::string::npos) << r.out;
    double w[3];
    ASSERT_EQ(std::sscanf(r.out.c_str() + at + std::strlen("c0.5: mean weights"),
                          " c0.5 %lf, c1.5 %lf, c2.5 %lf", &w[0], &w[1], &w[2]),
              3)
        << r.out;
    for (int j = 0; j < 3; ++j) {
      if (j == k) continue;
      EXPECT_GT(w[k], w[j]) << depths[k] << " N: " << r.out;
    }
    EXPECT_TRUE(std::filesystem::exists(dir / "sim" / fmt::format("c{}.csv", depths[k])));
  }
  // A directory without sets, and a set of another material, are named.
  r = test::run_kelvin("probe " + s + " -o " + (dir / "sim2").string() + " --blend " +
                       dir.string());
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("no sets/ directory there"), std::string::npos) << r.out;
  test::write_text(dir / "fit" / "sets" / "c0.5.csv", "element,elastic.E,elastic.nu\n0,1,0.3\n");
  r = test::run_kelvin("probe " + s + " -o " + (dir / "sim2").string() + " --blend " +
                       (dir / "fit").string());
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("c0.5.csv:1: the header must be element,elastic.lambda,elastic.mu,strain"),
            std::string::npos)
      << r.out;
}

namespace {

/// Marker rms (m) of a light (0.3 N, x = 0.01) and a deep (2.0 N, x = 0.03) contact
/// pressed at once, predicted from sets fitted to `training` probes: one set, and
/// the sets blended by the strain level and by the local metric.
std::array<double, 3> predict_light_and_deep(const std::vector<Probe>& training) {
  const Mesh mesh = generate_box({0, 0, 0}, {0.04, 0.04, 0.02}, 0.01);
  const auto top = nodes_where(mesh, [](const Eigen::Vector3d& X) { return X.z() > 0.0199; });
  std::vector<std::unique_ptr<FemModel>> models;
  std::vector<ObservedProbe> probes;
  std::vector<std::string> names;
  for (const Probe& probe : training) {
    const Eigen::Matrix3Xd x =
        equilibrium(*probed_model(mesh, "neo-hookean", uniform(mesh, kLambda, kMu), probe));
    models.push_back(probed_model(mesh, "corotational", uniform(mesh, kLambda, kMu), probe));
    probes.push_back(node_markers(*models.back(), top, x));
    names.push_back(fmt::format("{:.1f} N at x {:.3f}", -probe.force.z(), probe.at.x()));
  }
  DisplacementInverseOptions fit;
  fit.relative_tolerance = 1e-8;
  const std::vector<ParameterSet> sets = fit_parameter_sets(probes, names, fit);
  const DisplacementInverseResult single = displacement_based_inverse(probes, fit);

  auto two_probes = [&](const std::string& law, const Eigen::MatrixXd& q) {
    NodeSelection base;
    base.axis = 2, base.at = 0;
    std::vector<ClampBinding> clamps{
        {"table", select_nodes(mesh, base), std::make_shared<FixedMotion>()}};
    NodeLoad light{"light", {}, {0, 0, -0.3}, 0}, deep{"deep", {}, {0, 0, -2.0}, 0};
    for (int a = 0; a < mesh.num_nodes(); ++a) {
      const Eigen::Vector3d X = mesh.nodes.col(a);
      if (std::abs(X.z() - 0.02) > 1e-9) continue;
      if ((X.head<2>() - Eigen::Vector2d(0.01, 0.02)).norm() <= 0.006) light.nodes.push_back(a);
      if ((X.head<2>() - Eigen::Vector2d(0.03, 0.02)).norm() <= 0.006) deep.nodes.push_back(a);
    }
    std::vector<MaterialTerm> terms{{create_builtin_material(law), q, {}}};
    return std::make_unique<FemModel>(
        mesh, std::move(terms), Eigen::VectorXd::Constant(mesh.num_tets(), 60.0),
        Eigen::Vector3d::Zero(), clamps, true, std::vector<NodeLoad>{light, deep});
  };
  const Eigen::Matrix3Xd truth =
      equilibrium(*two_probes("neo-hookean", uniform(mesh, kLambda, kMu)));
  auto held = two_probes("corotational", single.q);
  const ObservedProbe seen = node_markers(*held, top, truth);
  std::array<double, 3> rms{marker_rms(seen, equilibrium(*held)), 0, 0};
  for (int b = 0; b < 2; ++b) {
    BlendOptions o;
    o.metric = b == 0 ? BlendMetric::kGlobal : BlendMetric::kLocal;
    const BlendedEquilibrium r = blended_equilibrium(*held, Blender(mesh, sets, o));
    EXPECT_GT(r.x.size(), 0) << r.message;
    EXPECT_TRUE(r.converged) << r.message;
    rms[1 + b] = r.x.size() ? marker_rms(seen, r.x) : INFINITY;
  }
  std::printf("light and deep at once: one set %.4f mm, strain level %.4f mm, local %.4f mm\n",
              1e3 * rms[0], 1e3 * rms[1], 1e3 * rms[2]);
  return rms;
}

}  // namespace

TEST(Blending, TheLocalMetricTakesEachPlacesSetWhereTheSetsStrainedThosePlaces) {
  // A light and a deep contact pressed at once strain the body unevenly: one strain
  // level for the whole body takes the deep sets everywhere, the local metric (Eq.
  // 6.11) takes the light set where the body is strained like the light contact
  // strained it. It compares strains place by place, so it needs sets that strained
  // the places the new contact strains: with sets from the same places it wins;
  // with sets from a probe at the centre only, it extrapolates each element's strain
  // and loses to the strain level.
  const std::array<double, 3> same_places = predict_light_and_deep({{{0.01, 0.02}, {0, 0, -0.3}},
                                                                    {{0.01, 0.02}, {0, 0, -2.0}},
                                                                    {{0.03, 0.02}, {0, 0, -0.3}},
                                                                    {{0.03, 0.02}, {0, 0, -2.0}}});
  EXPECT_LT(same_places[2], same_places[1]);
  EXPECT_LT(same_places[2], same_places[0]);
  const std::array<double, 3> centre_only = predict_light_and_deep({{{0.02, 0.02}, {0, 0, -0.4}},
                                                                    {{0.02, 0.02}, {0, 0, -1.0}},
                                                                    {{0.02, 0.02}, {0, 0, -1.6}},
                                                                    {{0.02, 0.02}, {0, 0, -2.2}}});
  EXPECT_GT(centre_only[2], centre_only[1]);
}

TEST(ProbeCli, ForceBasedSetsFromEveryNodesMarkerAreBlended) {
  // A marker on every node: probe-fit --sets with the force-based inverse writes the
  // sets of one linear solve, and probe --blend takes them like displacement-based ones.
  const auto dir = test::scratch("probe-force-sets");
  const Mesh mesh = generate_box({0, 0, 0}, {0.04, 0.04, 0.02}, 0.01);
  std::string markers = "name,x,y,z\n";
  for (int a = 0; a < mesh.num_nodes(); ++a)
    markers += fmt::format("n{},{:.17g},{:.17g},{:.17g}\n", a, mesh.nodes(0, a), mesh.nodes(1, a),
                           mesh.nodes(2, a));
  test::write_text(dir / "markers.csv", markers);
  auto scenario = [&](const std::string& law, const std::string& observed) {
    std::string s =
        "mesh: { generate: box, lo: [0, 0, 0], hi: [0.04, 0.04, 0.02], element_size: 0.01 }\n"
        "material: { density: 60, elastic: { model: " +
        law +
        ", lambda: 2e4, mu: 1e4 } }\n"
        "clamps: [{ name: table, select: { plane: { axis: z, at: 0 } } }]\n"
        "markers: { rest: markers.csv }\n"
        "probing:\n  method: force\n  measurements:\n";
    for (const char* f : {"0.5", "1.5", "2.5"})
      s += fmt::format(
          "    - {{ name: c{0}, loads: [{{ name: p, select: {{ box: {{ lo: [0.014, 0.014, "
          "0.0199], hi: [0.026, 0.026, 0.0201] }} }}, force: [0, 0, -{0}] }}]{1} }}\n",
          f, observed.empty() ? "" : fmt::format(", observed: {}/c{}.csv", observed, f));
    return s;
  };
  test::write_text(dir / "truth.yaml", scenario("neo-hookean", ""));
  test::CliRun r =
      test::run_kelvin("probe " + (dir / "truth.yaml").string() + " -o " + (dir / "seen").string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  test::write_text(dir / "s.yaml", scenario("corotational", (dir / "seen").string()));
  const std::string s = (dir / "s.yaml").string();
  r = test::run_kelvin("probe-fit " + s + " -o " + (dir / "fit").string() + " --sets");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  // The neo-Hookean foam stiffens under the deeper probes: their sets are stiffer.
  double mu[3];
  int k = 0;
  for (const char* f : {"0.5", "1.5", "2.5"}) {
    const std::string set = test::read_text(dir / "fit" / "sets" / fmt::format("c{}.csv", f));
    ASSERT_EQ(set.rfind("element,elastic.lambda,elastic.mu,strain.E11,", 0), 0u) << set;
    double lambda = 0;
    ASSERT_EQ(std::sscanf(set.c_str() + set.find('\n') + 1, "0,%lf,%lf", &lambda, &mu[k]), 2);
    ++k;
  }
  EXPECT_LT(mu[0], mu[1]);
  EXPECT_LT(mu[1], mu[2]);
  r = test::run_kelvin("probe " + s + " -o " + (dir / "sim").string() + " --blend " +
                       (dir / "fit").string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("blending 3 parameter sets"), std::string::npos) << r.out;
  r = test::run_kelvin("probe-fit " + s + " -o " + (dir / "cv").string() + " --cross-validate");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("--cross-validate fits with the displacement-based inverse"),
            std::string::npos)
      << r.out;
}
