// The gap diagnosis on small cases: the robust noise level, extended scenarios that
// leave the nominal model unchanged, and `kelvin diagnose`'s verdict on a shaken bar
// with an effect put into its tracks (named, with the misfit down to the noise) and
// without one (none).
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <fstream>
#include <random>

#include "adjoint/fit_problem.hpp"
#include "base/error.hpp"
#include "diagnose/candidates.hpp"
#include "diagnose/diagnose_settings.hpp"
#include "diagnose/diagnosis.hpp"
#include "diagnose/diagnosis_model.hpp"
#include "diagnose/diagnosis_outputs.hpp"
#include "diagnose/extended_scenario.hpp"
#include "diagnose/learned_correction.hpp"
#include "diagnose/noise.hpp"
#include "diagnosis_fixture.hpp"
#include "engine/csv.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;
using test::bar;
using test::diagnosis_case;
using test::kNominal;
using test::kWithDrag;

// White noise under a smooth model error 6× its size, with gaps: the third
// differences see the noise, ‖r‖ sees both.
TEST(NoiseEstimate, IgnoresASmoothModelErrorAndGaps) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0, 0.5e-3);
  std::vector<double> r;
  std::vector<ResidualSample> samples;
  for (int marker = 0; marker < 4; ++marker)
    for (int axis = 0; axis < 3; ++axis)
      for (int k = 0; k < 400; ++k) {
        if (k % 97 < 12) continue;  // occlusions
        const double t = k / 180.0;
        r.push_back(3e-3 * std::sin(2 * M_PI * 3 * t + marker) +
                    1e-3 * std::sin(2 * M_PI * 7.5 * t) + noise(rng));
        samples.push_back({0, marker, axis, t, 1});
      }
  const NoiseEstimate n = estimate_noise(Eigen::Map<Eigen::VectorXd>(r.data(), r.size()), samples);
  EXPECT_NEAR(n.sigma, 0.5e-3, 0.03e-3);
  EXPECT_GT(n.naive, 2e-3);
  EXPECT_GT(n.differences, 3500);

  // An odd first gap (a capture that starts at the release, 3.7 ms before its first
  // regular frame) costs the runs through it, not the whole estimate.
  for (auto& s : samples)
    if (s.t > 0) s.t += 0.0037 - 1 / 180.0;
  const NoiseEstimate shifted =
      estimate_noise(Eigen::Map<Eigen::VectorXd>(r.data(), r.size()), samples);
  EXPECT_NEAR(shifted.sigma, 0.5e-3, 0.03e-3);
  EXPECT_GT(shifted.differences, 3400);
}

// A bad diagnose section is refused with the file, line and key.
TEST(DiagnoseSettings, BadEntriesAreRefusedWithTheirPlace) {
  const fs::path dir = test::scratch("diagnose-settings");
  const auto refusal = [&](const std::string& section) -> std::string {
    test::write_text(dir / "s.yaml", "name: s\ndiagnose:\n" + section);
    try {
      load_diagnose_settings((dir / "s.yaml").string());
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(refusal("  refits: -1\n").find("s.yaml:3:11: diagnose.refits: must be in [0, 20]"),
            std::string::npos);
  EXPECT_NE(refusal("  candidates: [stifening]\n").find("did you mean 'stiffening'"),
            std::string::npos);
  EXPECT_NE(refusal("  validate: [missing.yaml]\n").find("diagnose.validate[0]"),
            std::string::npos);
  EXPECT_NE(refusal("  refit: 3\n").find("diagnose.refit"), std::string::npos);
  EXPECT_NE(refusal("  missing_force: maybe\n").find("diagnose.missing_force"), std::string::npos);
  EXPECT_NE(refusal("  missing_force: { segments: 0 }\n")
                .find("diagnose.missing_force.segments: must be in [1, 100]"),
            std::string::npos);
  EXPECT_NE(refusal("  missing_force: { knots_per_second: -2 }\n")
                .find("diagnose.missing_force.knots_per_second"),
            std::string::npos);
  EXPECT_NE(refusal("  missing_force: { knots: 3 }\n").find("diagnose.missing_force.knots"),
            std::string::npos);
  test::write_text(dir / "ok.yaml", "name: s\n");
  const DiagnoseSettings d = load_diagnose_settings((dir / "ok.yaml").string());
  EXPECT_EQ(d.refits, 3);
  EXPECT_TRUE(d.candidates.empty());
  EXPECT_TRUE(d.missing_force.enabled);
  EXPECT_TRUE(d.learned_correction);
  test::write_text(dir / "off.yaml", "name: s\ndiagnose:\n  missing_force: false\n");
  EXPECT_FALSE(load_diagnose_settings((dir / "off.yaml").string()).missing_force.enabled);
  // The learned correction is a fallback, not a candidate to screen: a list switches
  // it off unless it names it, and cannot name it alone.
  EXPECT_NE(refusal("  candidates: [unnamed]\n").find("names no candidate to screen"),
            std::string::npos);
  test::write_text(dir / "list.yaml", "name: s\ndiagnose:\n  candidates: [drag]\n");
  EXPECT_FALSE(load_diagnose_settings((dir / "list.yaml").string()).learned_correction);
  test::write_text(dir / "with.yaml", "name: s\ndiagnose:\n  candidates: [drag, unnamed]\n");
  const DiagnoseSettings w = load_diagnose_settings((dir / "with.yaml").string());
  EXPECT_TRUE(w.learned_correction);
  EXPECT_EQ(w.candidates, std::vector<std::string>{"drag"});
  // Leaving some out of the default keeps the rest, the learned correction included.
  test::write_text(dir / "without.yaml", "name: s\ndiagnose:\n  exclude: [discretisation, drag]\n");
  const DiagnoseSettings wo = load_diagnose_settings((dir / "without.yaml").string());
  EXPECT_TRUE(wo.candidates.empty());
  EXPECT_EQ(wo.exclude, (std::vector<std::string>{"discretisation", "drag"}));
  EXPECT_TRUE(wo.learned_correction);
  EXPECT_NE(refusal("  exclude: [dicretisation]\n").find("diagnose.exclude[0]"), std::string::npos);

  // The user's candidates: an identifier of their own, one term at most, parameters
  // to fit; `term.<p>` names the added term's parameter.
  const std::string fibre = "      elastic: { model: fibre, k: 0, theta: 0, phi: 0 }\n";
  const std::string k = "      parameters: [ { target: term.k, lower: 0 } ]\n";
  EXPECT_NE(refusal("  custom:\n    - id: Fibres\n" + fibre + k)
                .find("diagnose.custom[0].id: 'Fibres' is not an identifier"),
            std::string::npos);
  EXPECT_NE(refusal("  custom:\n    - id: drag\n" + fibre + k).find("'drag' is taken"),
            std::string::npos);
  EXPECT_NE(refusal("  custom:\n    - id: a\n" + fibre + k + "    - id: a\n" + fibre + k)
                .find("diagnose.custom[1].id: 'a' is taken"),
            std::string::npos);
  EXPECT_NE(
      refusal("  custom:\n    - id: a\n" + fibre + "      viscous: { model: drag, c: 0 }\n" + k)
          .find("not both"),
      std::string::npos);
  EXPECT_NE(refusal("  custom:\n    - id: a\n" + k).find("diagnose.custom[0].parameters[0].target"),
            std::string::npos);
  EXPECT_NE(refusal("  custom:\n    - id: a\n" + fibre + "      parameters: []\n").find("is empty"),
            std::string::npos);
  EXPECT_NE(refusal("  custom:\n    - id: a\n" + fibre).find("parameters"), std::string::npos);
  test::write_text(dir / "custom.yaml", "name: s\ndiagnose:\n  custom:\n    - id: fibres_x\n" +
                                            fibre + k + "  candidates: [drag, fibres_x]\n");
  const DiagnoseSettings c = load_diagnose_settings((dir / "custom.yaml").string());
  ASSERT_EQ(c.custom.size(), 1u);
  EXPECT_EQ(c.custom[0].id, "fibres_x");
  EXPECT_EQ(c.custom[0].kind, "elastic");
  EXPECT_NE(c.custom[0].place.find("custom.yaml:4:7: diagnose.custom[0]"), std::string::npos)
      << c.custom[0].place;
  EXPECT_EQ(c.candidates, (std::vector<std::string>{"drag", "fibres_x"}));
}

/// The nominal bar fitting μ and ν to noiseless tracks of `truth` (dir/nominal.yaml).
Scenario nominal_scenario(const fs::path& dir, const std::string& truth) {
  const std::string tracks =
      test::simulate_tracks(dir, "truth", bar(truth, test::kShakenBarMarkers));
  test::write_text(dir / "nominal.yaml",
                   bar(kNominal, test::kShakenBarMarkers + "\n  observed: " + tracks +
                                     "\nfit:\n  parameters: [elastic.mu, viscous.nu]\n"));
  return load_scenario((dir / "nominal.yaml").string());
}

// The truth of the nesting tests: the nominal bar 25 % stiffer in shear.
const std::string kStiffer = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 30 })";

// Every candidate switched on at its nominal value leaves Φ as it was: the nominal
// model is inside each extended family.
TEST(ExtendedScenario, EveryCandidateAtItsNominalValueChangesNothing) {
  const fs::path dir = test::scratch("diagnosis-nested");
  const Scenario nominal = nominal_scenario(dir, kStiffer);
  const std::vector<Candidate> all = builtin_candidates(nominal);
  std::vector<std::string> ids;
  for (const auto& c : all) ids.push_back(c.id);
  for (const char* id :
       {"stiffening", "damping_law", "drag", "inhomogeneity", "added_mass", "anisotropy",
        "relaxation", "sync_lag", "marker_offset", "registration", "clamp_compliance"})
    EXPECT_NE(std::find(ids.begin(), ids.end(), id), ids.end()) << id;
  FitProblem plain(nominal, nominal.fit.parameters);
  GradientOptions phi_only;  // Φ is the question; a gradient would triple the cost
  phi_only.method = GradientMethod::kNone;
  const Evaluation base = plain.evaluate(plain.map().initial(), phi_only);
  ASSERT_TRUE(base.ok) << base.error;

  // A compliant clamp's nominal pads are 10⁻⁵ of the body's compliance, not 0 (a
  // stiffer pad's force drowns in the round-off of the positions): its clamp face sinks
  // by that fraction of the load, which moves Φ by about 10⁻⁴.
  const auto pads = std::find_if(all.begin(), all.end(),
                                 [](const Candidate& c) { return c.id == "clamp_compliance"; });
  ASSERT_NE(pads, all.end());
  const ExtendedScenario soft =
      write_extended_scenario(nominal.path, nominal, {&*pads}, true, (dir / "pads.yaml").string());
  const Scenario padded_scenario = load_scenario(soft.path);
  FitProblem padded(padded_scenario, padded_scenario.fit.parameters);
  const Evaluation at_pads = padded.evaluate(padded.map().initial(), phi_only);
  ASSERT_TRUE(at_pads.ok) << at_pads.error;
  EXPECT_NEAR(at_pads.phi, base.phi, 1e-3 * base.phi);

  // The discretisation is the one candidate that is not nested: the mesh split into
  // eight, the nominal parameters alone.
  const auto mesh = std::find_if(all.begin(), all.end(),
                                 [](const Candidate& c) { return c.id == "discretisation"; });
  ASSERT_NE(mesh, all.end());
  EXPECT_FALSE(mesh->screened);
  EXPECT_EQ(mesh, all.end() - 1);  // the unscreened come last
  const Scenario refined = load_scenario(
      write_extended_scenario(nominal.path, nominal, {&*mesh}, false, (dir / "mesh.yaml").string())
          .path);
  EXPECT_EQ(refined.mesh.num_tets(), 8 * nominal.mesh.num_tets());
  EXPECT_EQ(refined.solver.lumped_mass, nominal.solver.lumped_mass);
  EXPECT_EQ(refined.markers.embedded.size(), nominal.markers.embedded.size());
  FitProblem fine(refined, refined.fit.parameters);
  ASSERT_EQ(fine.map().size(), plain.map().size());

  std::vector<const Candidate*> with;
  for (const auto& c : all)
    if (&c != &*pads && c.screened) with.push_back(&c);
  const ExtendedScenario ext =
      write_extended_scenario(nominal.path, nominal, with, true, (dir / "all.yaml").string());
  EXPECT_EQ(ext.nominal_specs, 2);
  ASSERT_EQ(ext.candidate_specs.size(), all.size() - 2);
  const Scenario extended = load_scenario(ext.path);
  // The neo-Hookean term, the stiffening one, one fibre per screened direction and
  // one relaxing branch per screened time.
  EXPECT_EQ(extended.material.elastic.size(),
            1u + 1u + screening_directions().size() + screening_relaxation_times(nominal).size());
  EXPECT_EQ(extended.material.viscous[0].model, "power-law");
  FitProblem wide(extended, extended.fit.parameters);
  for (int j = 0; j < plain.map().size(); ++j) EXPECT_EQ(wide.map().label(j), plain.map().label(j));
  const Evaluation e = wide.evaluate(wide.map().initial(), phi_only);
  ASSERT_TRUE(e.ok) << e.error;
  // Equal to the integration error (rtol 1e-7): the extra terms change the Newton
  // iterations' round-off, not the model.
  EXPECT_NEAR(e.phi, base.phi, 1e-6 * base.phi);
}

// The screening's Jacobian computed one candidate at a time (each in the nominal model
// extended by it alone, integrating its own sensitivities) is the joint model's: a
// nested candidate at its nominal value leaves the tracks where they were. Alone, a
// candidate at 0 also needs sensitivity weights of its own scale (with weights per |q|
// its columns came out 5–50× off: no nominal sensitivity kept the Newton iteration
// going). Agreement is to ~10⁻⁶ at rtol 10⁻⁷.
TEST(ScreeningSystem, PerCandidateColumnsAreTheJointModels) {
  const fs::path dir = test::scratch("diagnosis-screening-system");
  const Scenario nominal = nominal_scenario(dir, kStiffer);
  const std::vector<Candidate> all = builtin_candidates(nominal);
  // The compliant clamp's nominal pads are not exactly rigid (see above): its model
  // moves the tracks by 10⁻⁴, so the joint model is not the reference for it.
  std::vector<const Candidate*> with;
  for (const auto& c : all)
    if (c.screened && c.id != "clamp_compliance") with.push_back(&c);
  Model joint = load_model(nominal.path, nominal, with, true, (dir / "joint.yaml").string());
  Eigen::VectorXd p = joint.problem->map().initial();
  // μ and ν from 0.8e5 and 30 to 0.9e5 and 25, away from the fit: no column vanishes.
  ASSERT_TRUE(joint.problem->map().block_of_entry(0).log);
  p.head(2) += Eigen::Vector2d(std::log(0.9 / 0.8), std::log(25.0 / 30));
  const GaussNewtonSystem a = gauss_newton_system(*joint.problem, p);
  ASSERT_TRUE(a.ok) << a.error;
  const GaussNewtonSystem b =
      screening_system(joint, nominal.path, nominal, with, -1, p, dir, "parts", nullptr);
  ASSERT_TRUE(b.ok) << b.error;
  ASSERT_EQ(a.residual.size(), b.residual.size());
  EXPECT_LT((a.residual - b.residual).norm(), 1e-5 * a.residual.norm());
  ASSERT_EQ(a.jacobian.cols(), b.jacobian.cols());
  const ParameterMap& map = joint.problem->map();
  for (int j = 0; j < map.size(); ++j) {
    const double scale = a.jacobian.col(j).norm();
    EXPECT_GT(scale, 0) << map.label(j);
    EXPECT_LT((a.jacobian.col(j) - b.jacobian.col(j)).norm(), 1e-4 * scale) << map.label(j);
  }
}

// The learned correction is nested at zero, and its signature reads the refitted
// values as stress relative to the nominal's modulus.
TEST(LearnedCorrection, AtZeroChangesNothingAndItsSignatureReadsTheValues) {
  const fs::path dir = test::scratch("diagnosis-learned");
  const Scenario nominal = nominal_scenario(dir, kNominal);
  const Candidate c = learned_correction(nominal);
  EXPECT_EQ(c.id, "unnamed");
  const ExtendedScenario ext =
      write_extended_scenario(nominal.path, nominal, {&c}, false, (dir / "unnamed.yaml").string());
  const Scenario extended = load_scenario(ext.path);
  ASSERT_EQ(extended.material.elastic.size(), 2u);
  EXPECT_EQ(extended.material.elastic[1].model, "spline");
  EXPECT_EQ(extended.material.viscous[1].model, "strain-damping");
  // Four stretch and four volume knots within ±20 % of rest, d1 and d2 (the nominal
  // Newtonian term carries d0).
  ASSERT_EQ(ext.candidate_specs.size(), 1u);
  EXPECT_EQ(ext.candidate_specs[0].size(), 10u);
  GradientOptions phi_only;
  phi_only.method = GradientMethod::kNone;
  FitProblem plain(nominal, nominal.fit.parameters), wide(extended, extended.fit.parameters);
  const Evaluation a = plain.evaluate(plain.map().initial(), phi_only),
                   b = wide.evaluate(wide.map().initial(), phi_only);
  ASSERT_TRUE(a.ok && b.ok) << a.error << b.error;
  EXPECT_NEAR(b.phi, a.phi, 1e-6 * a.phi + 1e-18);

  // M = λ = 2e5 Pa: f′(1.1) = 2000 Pa is +10 % of M·0.1 (stiffer in stretch), h′(0.9) =
  // 4000 Pa is −20 % (a positive stress in compression: softer); ν = 30 Pa s.
  const CorrectionSignature sig = correction_signature(
      nominal, {{"elastic[1].f11", 2000}, {"elastic[1].h12", 4000}, {"viscous[1].d1", 30}});
  ASSERT_EQ(sig.points.size(), 4u);
  EXPECT_EQ(sig.points[0].kind, "stretch");
  EXPECT_DOUBLE_EQ(sig.points[0].at, 1.1);
  EXPECT_NEAR(sig.points[0].relative, 0.1, 1e-12);
  EXPECT_EQ(sig.points[1].kind, "volume");
  EXPECT_DOUBLE_EQ(sig.points[1].at, 0.9);
  EXPECT_NEAR(sig.points[1].relative, 0.2, 1e-12);
  // ν(1.2) − ν(1) = d1 · 0.2 = 6 Pa s, a fifth of the nominal's 30.
  EXPECT_EQ(sig.points[3].kind, "damping");
  EXPECT_NEAR(sig.points[3].relative, 0.2, 1e-12);
  EXPECT_NE(sig.summary.find("s > 1: stiffer"), std::string::npos) << sig.summary;
  EXPECT_NE(sig.summary.find("J < 1: softer"), std::string::npos) << sig.summary;
}

TEST(Diagnosis, NamesTheEffectInTheDataAndHowFarItShrinksTheGap) {
  const fs::path dir = test::scratch("diagnosis-drag");
  const fs::path scenario = diagnosis_case(dir, kWithDrag, 7);
  DiagnoseOptions o;
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), o);
  write_diagnosis_outputs(d);
  EXPECT_EQ(d.effect, "drag");
  ASSERT_GE(d.accepted, 0);
  const RefitResult& a = d.refits[d.accepted];
  // The noise is 0.01 mm; the refit's training and held-out RMS come down to it.
  EXPECT_NEAR(d.noise.sigma, 1e-5, 0.15e-5);
  EXPECT_GT(d.nominal_train.rms, 3 * d.noise.sigma);
  EXPECT_LT(a.train.rms, 1.3 * d.noise.sigma);
  ASSERT_EQ(a.heldout.size(), 1u);
  EXPECT_LT(a.heldout[0].after.rms, 1.3 * d.noise.sigma);
  EXPECT_GT(a.heldout[0].before.rms, 2 * a.heldout[0].after.rms);
  ASSERT_EQ(a.parameters.size(), 1u);
  EXPECT_NEAR(a.parameters[0].value, 40, 4);
  // Standard errors: the drag's from its refit, the nominal ones from the screening's
  // columns, which the drag the nominal model lacks widens far beyond the refit's.
  EXPECT_LT(std::abs(a.parameters[0].value - 40), 5 * a.parameters[0].std_error);
  ASSERT_EQ(d.nominal_parameters.size(), 2u);
  ASSERT_EQ(a.nominal_parameters.size(), 2u);
  for (int j = 0; j < 2; ++j)
    EXPECT_GT(d.nominal_parameters[j].std_error, 5 * a.nominal_parameters[j].std_error) << j;
  // The missing force explains the gap and sits where the drag −cρv is largest,
  // at the free end, which moves most.
  const MissingForce& f = d.missing_force;
  ASSERT_TRUE(f.ok) << f.error;
  EXPECT_GT(f.statistic, f.threshold);
  EXPECT_LT(f.rms_after, 0.3 * f.rms_before);
  EXPECT_EQ(f.where, "free end");
  EXPECT_TRUE(fs::exists(dir / "out" / "missing-force" / "body-force.pvd"));
  // Screened again with the drag in the model, nothing else is left to explain, and
  // the missing force of the model with it fits no more than noise.
  EXPECT_FALSE(d.second_ranking.order.empty());
  EXPECT_EQ(d.second_candidate, -1);
  ASSERT_TRUE(d.remaining_force.ok) << d.remaining_force.error;
  // It starts from the refit, not the nominal (0.35 mm): its rms is Φ's time
  // integral and the refit's the frames', which differ by a few per cent.
  EXPECT_NEAR(d.remaining_force.rms_before, a.train.rms, 0.1 * a.train.rms);
  EXPECT_LT(d.remaining_force.statistic, d.remaining_force.threshold);
  EXPECT_TRUE(fs::exists(dir / "out" / "heldout.svg"));
  EXPECT_EQ(d.learned, -1);  // a named effect passed: no learned correction
  EXPECT_TRUE(fs::exists(dir / "out" / "diagnosis.json"));
  EXPECT_TRUE(fs::exists(dir / "out" / "report.md"));
  // fitted.yaml is the extended model: it runs and names the drag.
  const Scenario fitted = load_scenario((dir / "out" / "fitted.yaml").string());
  ASSERT_EQ(fitted.material.viscous.size(), 2u);
  EXPECT_EQ(fitted.material.viscous[1].model, "drag");
}

/// Moves marker `name`'s captured track by `delta` along `axis` (a marker glued off
/// the place the scenario gives it), keeping the file's layout.
void shift_marker(const fs::path& file, const std::string& name, int axis, double delta) {
  MarkerTracks t = read_marker_tracks(file.string());
  const long row = 3 * (std::find(t.names.begin(), t.names.end(), name) - t.names.begin()) + axis;
  ASSERT_LT(row, t.xyz.rows());
  t.xyz.row(row).array() += delta;
  test::write_marker_tracks(t, file);
}

// Two effects at once: the bar drags in air and its tip marker sits 0.04 mm (4σ)
// off where the scenario puts it, in both motions. The larger one, the drag, is
// named first; screened again with it in the model, the offset is significant, and
// its refit with the drag at its refit passes on the training and held-out data, so
// it is named as the second effect with the offset it has.
TEST(Diagnosis, NamesASecondEffectWhenItsRefitPassesAsTheFirstDid) {
  const fs::path dir = test::scratch("diagnosis-two-effects");
  const fs::path scenario = diagnosis_case(dir, kWithDrag, 23, "drag, marker_offset");
  shift_marker(dir / "train.csv", "tip", 1, 4e-5);
  shift_marker(dir / "heldout.csv", "tip", 1, 4e-5);
  DiagnoseOptions o;
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), o);
  write_diagnosis_outputs(d);
  EXPECT_EQ(d.effect, "drag");
  ASSERT_GE(d.second_candidate, 0);
  EXPECT_EQ(d.candidates[d.second_candidate].id, "marker_offset");
  EXPECT_EQ(d.candidates[d.second_candidate].where, "tip");
  const RefitResult& s = d.second_refit;
  ASSERT_TRUE(s.ok) << s.error;
  EXPECT_EQ(s.candidate, d.second_candidate);
  EXPECT_EQ(d.candidates[s.on_top_of].id, "drag");
  EXPECT_EQ(d.second_effect, "marker_offset");
  // Against the model with the drag, both the training and held-out misfits drop by
  // more than noise, and the two together leave only noise.
  const RefitResult& a = d.refits[d.accepted];
  EXPECT_GT(s.statistic, s.threshold);
  EXPECT_GT(s.heldout_drop, s.heldout_threshold);
  EXPECT_GT(a.train.rms, 1.5 * d.noise.sigma);
  EXPECT_LT(s.train.rms, 1.3 * d.noise.sigma);
  ASSERT_EQ(s.parameters.size(), 3u);
  // σ/√frames per coordinate: 0.01 mm over 101 frames.
  EXPECT_NEAR(s.parameters[1].std_error, 1e-6, 0.3e-6);
  EXPECT_NEAR(s.parameters[1].value, 4e-5, 4 * s.parameters[1].std_error);
  EXPECT_NEAR(s.parameters[0].value, 0, 0.5e-5);
  EXPECT_NEAR(s.parameters[2].value, 0, 0.5e-5);
  // The fitted scenario holds both: the drag in the material, the offset noted.
  EXPECT_EQ(d.fitted_yaml, s.fitted_yaml);
  const Scenario fitted = load_scenario(d.fitted_yaml);
  ASSERT_EQ(fitted.material.viscous.size(), 2u);
  EXPECT_EQ(fitted.material.viscous[1].model, "drag");
  // diagnosis.json (read as YAML, of which JSON is a subset) holds the same figures,
  // to its ten digits, under their keys.
  const YAML::Node json = YAML::LoadFile((dir / "out" / "diagnosis.json").string());
  EXPECT_EQ(json["verdict"]["effect"].as<std::string>(), "drag");
  EXPECT_EQ(json["verdict"]["second_effect"].as<std::string>(), "marker_offset");
  EXPECT_NEAR(json["nominal"]["train_rms"].as<double>(), d.nominal_train.rms,
              1e-8 * std::abs(d.nominal_train.rms));
  EXPECT_NEAR(json["nominal"]["parameters"][0]["std_error"].as<double>(),
              d.nominal_parameters[0].std_error,
              1e-8 * std::abs(d.nominal_parameters[0].std_error));
  const YAML::Node second = json["second_refit"];
  EXPECT_EQ(second["added_to"].as<std::string>(), "drag");
  EXPECT_NEAR(second["train_rms_before"].as<double>(), a.train.rms, 1e-8 * std::abs(a.train.rms));
  EXPECT_NEAR(second["train_rms_after"].as<double>(), s.train.rms, 1e-8 * std::abs(s.train.rms));
  EXPECT_NEAR(second["parameters"][1]["std_error"].as<double>(), s.parameters[1].std_error,
              1e-8 * std::abs(s.parameters[1].std_error));
}

// A marker re-glued between two captures: the tip sits 0.04 mm off in the training
// motion only. The second screening flags its offset and the refit explains the
// training tracks better, but the held-out motion, whose tip is where the scenario
// puts it, gets no better: no second effect, and fitted.yaml is the drag's alone.
TEST(Diagnosis, ASecondCandidateTheHeldOutMotionDoesNotConfirmIsNotNamed) {
  const fs::path dir = test::scratch("diagnosis-second-rejected");
  const fs::path scenario = diagnosis_case(dir, kWithDrag, 23, "drag, marker_offset");
  shift_marker(dir / "train.csv", "tip", 1, 4e-5);
  DiagnoseOptions o;
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), o);
  EXPECT_EQ(d.effect, "drag");
  ASSERT_GE(d.second_candidate, 0);
  EXPECT_EQ(d.candidates[d.second_candidate].where, "tip");
  const RefitResult& s = d.second_refit;
  ASSERT_TRUE(s.ok) << s.error;
  EXPECT_TRUE(s.passes_training);
  EXPECT_FALSE(s.passes_heldout);
  EXPECT_LT(s.heldout_drop, 0);  // the offset moves the held-out tip away from its track
  EXPECT_EQ(d.second_effect, "");
  EXPECT_EQ(d.fitted_yaml, d.refits[d.accepted].fitted_yaml);
}

// Interrupted in its first refit, a diagnosis keeps the nominal fit and nothing of
// the refit it stopped; --resume reuses the first, redoes the second, and comes to
// the verdict an uninterrupted run gives.
TEST(Diagnosis, AnInterruptedDiagnosisResumesWhereItStopped) {
  const fs::path dir = test::scratch("diagnosis-resume");
  const fs::path scenario = diagnosis_case(dir, kWithDrag, 7, "drag, sync_lag");
  std::atomic<bool> interrupt{false};
  std::string first, second;
  DiagnoseOptions o;
  o.interrupt = &interrupt;
  o.progress = [&](const std::string& line) {
    first += line + "\n";
    if (line.find("drag: eval") != std::string::npos) interrupt = true;
  };
  const Diagnosis a = run_diagnosis(scenario.string(), (dir / "out").string(), o);
  EXPECT_TRUE(a.interrupted);
  EXPECT_NE(first.find("drag: eval"), std::string::npos) << first;
  EXPECT_TRUE(fs::exists(dir / "out" / "state" / "nominal.csv"));
  EXPECT_FALSE(fs::exists(dir / "out" / "state" / "drag.csv"));

  interrupt = false;
  o.resume = true;
  o.progress = [&](const std::string& line) { second += line + "\n"; };
  const Diagnosis b = run_diagnosis(scenario.string(), (dir / "out").string(), o);
  EXPECT_NE(second.find("nominal: resumed from"), std::string::npos) << second;
  EXPECT_EQ(second.find("drag: resumed from"), std::string::npos) << second;
  EXPECT_EQ(b.nominal_parameters.size(), a.nominal_parameters.size());
  for (std::size_t j = 0; j < a.nominal_parameters.size() && j < b.nominal_parameters.size(); ++j)
    EXPECT_EQ(b.nominal_parameters[j].value, a.nominal_parameters[j].value);
  EXPECT_EQ(b.effect, "drag") << second;
  ASSERT_GE(b.accepted, 0);
  ASSERT_EQ(b.refits[b.accepted].parameters.size(), 1u);
  EXPECT_NEAR(b.refits[b.accepted].parameters[0].value, 40, 4);
}

// A relaxing branch in the data (the standard linear solid) is told from the other
// damping and stiffening candidates: it stiffens the fast motion and damps most where
// ωτ ≈ 1, which neither a stiffer modulus, a viscosity nor drag can do at both of
// the motions' frequencies.
TEST(Diagnosis, NamesARelaxingBranch) {
  const fs::path dir = test::scratch("diagnosis-relaxation");
  const std::string truth = R"(  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: maxwell, g: 4.0e4, tau: 0.01 }
  viscous: { model: newtonian, nu: 20 })";
  // Four parameters refitted together (μ, ν, g, τ; ν and gτ trade off) take more
  // than the default 40 evaluations to reach the noise.
  const fs::path scenario = diagnosis_case(dir, truth, 11, "stiffening, drag, relaxation",
                                           "  missing_force: false\n  refit_evaluations: 100\n");
  DiagnoseOptions o;
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), o);
  write_diagnosis_outputs(d);
  EXPECT_EQ(d.effect, "relaxation");
  ASSERT_GE(d.accepted, 0);
  const RefitResult& a = d.refits[d.accepted];
  EXPECT_GT(d.nominal_train.rms, 3 * d.noise.sigma);
  EXPECT_LT(a.train.rms, 1.3 * d.noise.sigma);
  ASSERT_EQ(a.heldout.size(), 1u);
  EXPECT_LT(a.heldout[0].after.rms, 1.3 * d.noise.sigma);
  ASSERT_EQ(a.parameters.size(), 2u);
  EXPECT_NEAR(a.parameters[0].value, 4.0e4, 0.1 * 4.0e4);
  EXPECT_NEAR(a.parameters[1].value, 0.01, 0.1 * 0.01);
  const Scenario fitted = load_scenario((dir / "out" / "fitted.yaml").string());
  ASSERT_EQ(fitted.material.elastic.size(), 2u);
  EXPECT_EQ(fitted.material.elastic[1].model, "maxwell");
}

TEST(Diagnosis, FindsNoEffectWhereThereIsNone) {
  const fs::path dir = test::scratch("diagnosis-none");
  const std::string truth = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })";
  const fs::path scenario = diagnosis_case(dir, truth, 11);
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), {});
  EXPECT_EQ(d.effect, "none");
  EXPECT_LT(d.nominal_train.rms, 1.3 * d.noise.sigma);
  EXPECT_TRUE(std::none_of(d.ranking.order.begin(), d.ranking.order.end(),
                           [](const RankedCandidate& r) { return r.significant; }));
  // With nothing missing, the field fits no more than noise would let it.
  ASSERT_TRUE(d.missing_force.ok) << d.missing_force.error;
  EXPECT_LT(d.missing_force.statistic, d.missing_force.threshold);
  // Nor is the nominal residual above the noise: no learned correction is fitted.
  EXPECT_EQ(d.learned, -1);
}

/// A candidate of the user's: fibres along the bar (x), their stiffness fitted from 0.
std::string fibres_along_x(double k) {
  return fmt::format(R"(  missing_force: false
  custom:
    - id: fibres_along_x
      description: fibres along the bar
      where: whole body
      elastic: {{ model: fibre, k: {}, theta: 1.5707963267948966, phi: 0 }}
      parameters: [ {{ target: term.k, lower: 0 }} ]
)",
                     k);
}

// The user names an effect of their own in diagnose.custom; the data hold it, and the
// diagnosis names it beside the built-in candidates, with the user's place. A
// candidate that does not contain the nominal model is refused before any fit.
TEST(Diagnosis, NamesTheUsersOwnCandidate) {
  const fs::path dir = test::scratch("diagnosis-custom");
  const std::string truth = R"(  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 0.8e5 }
    - { model: fibre, k: 1.0e5, theta: 1.5707963267948966, phi: 0 }
  viscous: { model: newtonian, nu: 30 })";
  const fs::path scenario =
      diagnosis_case(dir, truth, 19, "drag, sync_lag, fibres_along_x", fibres_along_x(0));
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), {});
  write_diagnosis_outputs(d);
  EXPECT_EQ(d.effect, "fibres_along_x");
  ASSERT_GE(d.accepted, 0);
  const RefitResult& a = d.refits[d.accepted];
  ASSERT_FALSE(d.verdict_where.empty());
  EXPECT_EQ(d.verdict_where[0], "whole body");
  ASSERT_EQ(a.parameters.size(), 1u);
  EXPECT_NEAR(a.parameters[0].value, 1.0e5, 0.05e5);
  EXPECT_LT(a.train.rms, 1.3 * d.noise.sigma);
  ASSERT_EQ(a.heldout.size(), 1u);
  EXPECT_LT(a.heldout[0].after.rms, 1.3 * d.noise.sigma);

  const fs::path bad = diagnosis_case(test::scratch("diagnosis-custom-bad"), truth, 19,
                                      "fibres_along_x", fibres_along_x(2e4));
  try {
    run_diagnosis(bad.string(), (bad.parent_path() / "out").string(), {});
    ADD_FAILURE() << "a candidate that moves the nominal tracks was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("diagnose.custom[0]: is not nested"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("train.yaml:"), std::string::npos) << e.what();
  }
}

// Tracks of the same material on a finer mesh (each tetrahedron split into eight):
// the coarse nominal mesh is too stiff and its fit bends μ to make
// up for it. The diagnosis names the numerical cause, not a physical one, and the
// refit on the finer mesh recovers the true μ.
TEST(Diagnosis, ACoarseMeshIsNamedAsTheDiscretisationNotAsPhysics) {
  const fs::path dir = test::scratch("diagnosis-mesh");
  const std::string truth = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })";
  const fs::path scenario = diagnosis_case(dir, truth, 17, "stiffening, drag, discretisation",
                                           "  missing_force: false\n", true);
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), {});
  write_diagnosis_outputs(d);
  EXPECT_EQ(d.effect, "discretisation");
  ASSERT_GE(d.accepted, 0);
  const RefitResult& a = d.refits[d.accepted];
  EXPECT_EQ(a.dof, 0);
  ASSERT_EQ(a.heldout.size(), 1u);
  EXPECT_GT(d.nominal_train.rms, 3 * d.noise.sigma);
  EXPECT_LT(a.train.rms, 1.3 * d.noise.sigma);
  EXPECT_LT(a.heldout[0].after.rms, 1.3 * d.noise.sigma);
  ASSERT_EQ(a.nominal_parameters.size(), 2u);
  EXPECT_EQ(a.nominal_parameters[0].name, "elastic.mu");
  EXPECT_NEAR(a.nominal_parameters[0].value, 1.0e5, 0.02e5);
  EXPECT_LT(d.nominal_parameters[0].value, 0.95e5);  // the stiff coarse mesh's μ
  ASSERT_FALSE(d.verdict_where.empty());
  EXPECT_EQ(d.verdict_where[0], "mesh");
}

// A bulk modulus three times the nominal's: at these strains no named candidate
// (drag, a clock offset) can stand in for it, and the fitted μ
// cannot match both the bar's bending (E) and its shear (μ). The learned correction's
// volume spline h′(J) can: the gap is named "unnamed", and its signature says the
// body is stiffer in volume than the model.
TEST(Diagnosis, ALearnedCorrectionTakesAGapNoNamedCandidateExplains) {
  const fs::path dir = test::scratch("diagnosis-unnamed");
  const std::string truth = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 6.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })";
  // Without the missing force (its own tests are above): the nominal residual's F
  // test against the noise is what calls for the correction.
  const fs::path scenario =
      diagnosis_case(dir, truth, 13, "drag, sync_lag, unnamed", "  missing_force: false\n");
  const Diagnosis d = run_diagnosis(scenario.string(), (dir / "out").string(), {});
  write_diagnosis_outputs(d);
  ASSERT_GE(d.learned, 0);
  const RefitResult& x = d.refits[d.learned];
  ASSERT_TRUE(x.ok) << x.error;
  EXPECT_EQ(d.effect, "unnamed");
  // The nominal leaves twice the noise (0.01 mm); the correction brings the
  // training misfit down to it and halves the held-out one.
  EXPECT_GT(d.nominal_train.rms, 1.5 * d.noise.sigma);
  EXPECT_LT(x.train.rms, 1.2 * d.noise.sigma);
  ASSERT_EQ(x.heldout.size(), 1u);
  EXPECT_LT(x.heldout[0].after.rms, 0.5 * x.heldout[0].before.rms);
  double volume_tension = NAN;
  for (const auto& p : d.signature.points)
    if (p.kind == "volume" && p.at == 1.1) volume_tension = p.relative;
  EXPECT_GT(volume_tension, 0) << d.signature.summary;
  EXPECT_TRUE(fs::exists(dir / "out" / "heldout.svg"));
  const Scenario fitted = load_scenario((dir / "out" / "fitted.yaml").string());
  EXPECT_EQ(fitted.material.elastic.back().model, "spline");
}

}  // namespace
}  // namespace kelvin
