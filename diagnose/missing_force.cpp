#include "diagnose/missing_force.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include "adjoint/score_screening.hpp"
#include "base/error.hpp"
#include "engine/output.hpp"
#include "fit/body_force_outputs.hpp"
#include "fit/fit_loop.hpp"
#include "fit/fitted_scenario.hpp"
#include "yaml/scenario_paths.hpp"
#include "yaml/yaml_util.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

/// `segments` boxes along the body's axis, each spanning the mesh across it (a
/// little wider, so that every centroid lies in one; the first that holds it wins).
YAML::Node axis_boxes(const Mesh& mesh, const BodyAxis& axis, int segments) {
  const Eigen::Vector3d lo = mesh.nodes.rowwise().minCoeff(), hi = mesh.nodes.rowwise().maxCoeff();
  const double pad = 1e-6 * (hi - lo).norm();
  YAML::Node boxes(YAML::NodeType::Sequence);
  for (int k = 0; k < segments; ++k) {
    const double a = axis.clamp_end + (axis.free_end - axis.clamp_end) * k / segments;
    const double b = axis.clamp_end + (axis.free_end - axis.clamp_end) * (k + 1) / segments;
    Eigen::Vector3d mn = lo.array() - pad, mx = hi.array() + pad;
    mn[axis.axis] = std::min(a, b) - pad;
    mx[axis.axis] = std::max(a, b) + pad;
    YAML::Node box;
    for (int i = 0; i < 3; ++i) {
      box["min"].push_back(mn[i]);
      box["max"].push_back(mx[i]);
    }
    box["min"].SetStyle(YAML::EmitterStyle::Flow);
    box["max"].SetStyle(YAML::EmitterStyle::Flow);
    boxes.push_back(box);
  }
  return boxes;
}

/// The median spacing of the capture's frames (s).
double frame_spacing(const Scenario& s) {
  const auto& t = s.markers.observed.times;
  std::vector<double> dt;
  for (std::size_t k = 1; k < t.size(); ++k)
    if (t[k] > t[k - 1]) dt.push_back(t[k] - t[k - 1]);
  if (dt.empty()) return s.time.end;
  std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
  return dt[dt.size() / 2];
}

/// fit_missing_force but for the seconds it took.
MissingForce fit_field(FitProblem& problem, const Scenario& nominal,
                       const Eigen::VectorXd& p_nominal, const BodyAxis& axis,
                       const MissingForceNoise& noise, const MissingForceSettings& settings,
                       const std::string& dir, const std::atomic<bool>* interrupt,
                       const std::function<void(const std::string&)>& progress,
                       Communicator& comm) {
  MissingForce mf;
  fs::create_directories(dir);
  // The nominal model at its fit, as a scenario of its own: the field is fitted
  // with the nominal parameters held.
  FemModel& nominal_model = problem.experiment(0).model();
  problem.map().apply(p_nominal, nominal_model);
  const std::string held = write_fitted_scenario(nominal, problem.map(), nominal_model, dir);

  // At most one knot per two frames: the capture resolves no faster force.
  const double dt = frame_spacing(nominal);
  mf.knots = static_cast<int>(
      std::clamp(std::round(settings.knots_per_second * nominal.time.end), 1.0,
                 std::clamp(std::floor(0.5 * nominal.time.end / dt), 1.0, 2000.0)));
  mf.segments = settings.segments;
  const double g = nominal.gravity.norm() > 0 ? nominal.gravity.norm() : 1.0;
  // MAP with noise σ per coordinate and frame (Φ ≈ ½ Δt ‖r‖²) and a prior of size g
  // per coefficient: Φ + ½ σ² Δt Σ (a/g)².
  const double penalty = 0.5 * noise.sigma * noise.sigma * dt;
  const yamlutil::Doc doc(held);
  YAML::Node root = YAML::Clone(doc.root());
  root.remove("diagnose");
  YAML::Node fit = yaml_child(root, "fit");
  fit = fit.IsDefined() && fit.IsMap() ? YAML::Clone(fit) : YAML::Node(YAML::NodeType::Map);
  for (const char* key : {"experiments", "lcurve", "smoothness", "max_evaluations"})
    fit.remove(key);
  YAML::Node params(YAML::NodeType::Sequence);
  for (const char* target : {"body_force.x", "body_force.y", "body_force.z"}) {
    YAML::Node p;
    p["target"] = target;
    p["knots"] = mf.knots;
    p["penalty"] = penalty;
    p["scale"] = g;
    p["scope"]["boxes"] = axis_boxes(nominal.mesh, axis, mf.segments);
    params.push_back(p);
  }
  fit["parameters"] = params;
  // The fit's usual stages: the first at min(1e-3, 100 rtol), where an evaluation of
  // V09's 954 coefficients cost 9 s against 25 s at the scenario's rtol 1e-4.
  fit.remove("start_rtol");
  root["fit"] = fit;
  YAML::Emitter e;
  e << root;
  const std::string path = (fs::path(dir) / "missing-force.yaml").string();
  write_file_atomic(path, fmt::format("# Written by kelvin diagnose: the body-force field that "
                                      "makes the nominal model follow the capture.\n{}\n",
                                      e.c_str()));

  try {
    const Scenario s = load_scenario(path);
    FitProblem force(s, s.fit.parameters, comm);
    mf.dof = force.map().size();
    mf.threshold = chi_square_quantile(noise.alpha, mf.dof);
    // Both ends are measured at the scenario's tolerances, the stages' being coarser.
    // Per coordinate: Φ integrates ‖x − x̄‖², three coordinates' squares.
    GradientOptions exact;
    exact.method = GradientMethod::kNone;
    exact.interrupt = interrupt;
    const Evaluation before = force.evaluate(force.map().initial(), exact);
    if (!before.ok) {
      mf.error = before.error;
      return mf;
    }
    mf.rms_before = before.rms / std::sqrt(3.0);
    FitOptions o = fit_options_of(s);
    o.max_evaluations = settings.evaluations;
    o.gradient.interrupt = interrupt;
    // The verdict is the statistic against its threshold: a gain in Φ below a tenth
    // of the threshold (in σ̂² units) is none. V01's field gained 0.0006 mm of 0.47 mm
    // RMS over 17 evaluations after the third, at LR 25 against 1 058.
    const double resolved = 0.1 * mf.threshold * noise.sigma * noise.sigma;
    o.precision = resolved / std::max(noise.samples * mf.rms_before * mf.rms_before, 1e-300);
    o.start_objective = before.phi;
    o.on_evaluation = [&](const FitRecord& r) {
      if (progress && r.accepted)
        progress(fmt::format("  missing force: eval {:3d}  rms {:8.4f} mm  {:7.1f} s", r.evaluation,
                             r.rms / std::sqrt(3.0) * 1e3, r.seconds));
    };
    const FitOutcome out = run_fit(force, force.map().initial(), o);
    mf.evaluations = out.evaluations;
    if (!out.best.evaluation || out.history.empty()) {
      mf.error = out.history.empty() ? out.stop_reason : out.history.back().error;
      return mf;
    }
    if (out.best.tolerance_scale == 1) {
      mf.rms_after = out.best.rms / std::sqrt(3.0);
    } else {
      const Evaluation after = force.evaluate(out.p, exact);
      if (!after.ok) {
        mf.error = after.error;
        return mf;
      }
      mf.rms_after = after.rms / std::sqrt(3.0);
    }
    // A field no better than none at the scenario's tolerances (its gain was the
    // coarse stage's integration error) is not kept: the report shows none.
    Eigen::VectorXd p = out.p;
    if (mf.rms_after >= mf.rms_before) {
      p = force.map().initial();
      mf.rms_after = mf.rms_before;
    }
    mf.statistic = noise.samples * (mf.rms_before * mf.rms_before - mf.rms_after * mf.rms_after) /
                   (noise.sigma * noise.sigma);
    FemModel& model = force.experiment(0).model();
    force.map().apply(p, model);
    mf.files = write_body_force(model, dir);

    // Summaries per third of the body and per knot.
    const Mesh& mesh = model.mesh();
    const BodyForceField& field = model.body_force();
    const char* names[3] = {"clamp zone", "middle", "free end"};
    double energy[3] = {0, 0, 0}, volume[3] = {0, 0, 0};
    std::vector<double> per_knot(field.knots(), 0.0);
    for (int el = 0; el < mesh.num_tets(); ++el) {
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (int a = 0; a < 4; ++a) c += 0.25 * mesh.nodes.col(mesh.tets(a, el));
      const int r = std::clamp(static_cast<int>(3 * axis.along(c)), 0, 2);
      const double V = model.elements()[el].volume, rho = model.density()[el];
      volume[r] += V;
      for (int k = 0; k < field.knots(); ++k) {
        double f2 = 0;
        for (int i = 0; i < 3; ++i) f2 += std::pow(rho * field.value(i, k, el), 2);
        energy[r] += V * f2;
        per_knot[k] += V * f2;
      }
    }
    const double total = energy[0] + energy[1] + energy[2];
    int top = 0;
    for (int r = 0; r < 3; ++r) {
      MissingForceRegion region;
      region.name = names[r];
      region.rms_force = volume[r] > 0 ? std::sqrt(energy[r] / (volume[r] * field.knots())) : 0;
      region.share = total > 0 ? energy[r] / total : 0;
      if (energy[r] > energy[top]) top = r;
      mf.regions.push_back(region);
    }
    if (total > 0) {
      mf.where = names[top];
      mf.peak_time = field.knot_time(
          static_cast<int>(std::max_element(per_knot.begin(), per_knot.end()) - per_knot.begin()));
    }
    mf.ok = true;
  } catch (const Error& err) {
    mf.error = err.what();
  }
  return mf;
}

}  // namespace

MissingForce fit_missing_force(FitProblem& problem, const Scenario& nominal,
                               const Eigen::VectorXd& p_nominal, const BodyAxis& axis,
                               const MissingForceNoise& noise, const MissingForceSettings& settings,
                               const std::string& dir, const std::atomic<bool>* interrupt,
                               const std::function<void(const std::string&)>& progress,
                               Communicator& comm) {
  const auto t0 = std::chrono::steady_clock::now();
  MissingForce mf =
      fit_field(problem, nominal, p_nominal, axis, noise, settings, dir, interrupt, progress, comm);
  mf.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return mf;
}

}  // namespace kelvin
