// `kelvin probe` and `kelvin probe-fit`: static probing (Bächer 2008). `probe`
// simulates each measurement of a scenario's `probing:` section and writes the
// markers' loaded positions; `probe-fit` fits the elastic parameters to measured
// ones with the displacement-based or the force-based inverse.
#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <memory>

#include "base/error.hpp"
#include "drivers/commands.hpp"
#include "engine/output.hpp"
#include "probing/parameter_sets.hpp"
#include "probing/probe_experiment.hpp"
#include "probing/probing_system.hpp"

namespace kelvin {
namespace {

struct Args {
  std::string scenario, outdir = "out";
  std::string method, grouping;
  double gamma = -1;
  bool sets = false, cross_validate = false;
  std::string blend;              // a probe-fit output directory with sets/
  std::string metric = "global";  // of the blend
  double radius = 0;              // of the local metric (m); 0: twice the element size
};

BlendOptions blend_options(const Args& a) {
  BlendOptions o;
  o.metric = a.metric == "local" ? BlendMetric::kLocal : BlendMetric::kGlobal;
  o.radius = a.radius;
  return o;
}

/// The parameter sets of a probe-fit output directory (DIR/sets/*.csv, by name).
std::vector<ParameterSet> read_sets(const std::string& dir, const FemModel& model) {
  namespace fs = std::filesystem;
  const fs::path where = fs::path(dir) / "sets";
  std::error_code ec;
  if (!fs::is_directory(where, ec))
    throw Error(
        fmt::format("--blend {}: no sets/ directory there (kelvin probe-fit --sets "
                    "writes one)",
                    dir));
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(where, ec))
    if (entry.path().extension() == ".csv") files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) throw Error(fmt::format("--blend {}: sets/ holds no .csv file", dir));
  std::vector<std::string> names;
  const int term = elastic_term(model);
  for (const auto& info : model.terms()[term].model->params()) names.push_back(info.name);
  std::vector<ParameterSet> sets;
  for (const auto& f : files)
    sets.push_back(
        read_parameter_set(f.string(), f.stem().string(), names, model.mesh().num_tets()));
  return sets;
}

std::string positions_csv(const std::vector<MarkerEmbedding>& markers, const Eigen::Matrix3Xd& x) {
  std::string s = "name,x,y,z\n";
  for (size_t j = 0; j < markers.size(); ++j)
    s += fmt::format("{},{:.9g},{:.9g},{:.9g}\n", markers[j].name, x(0, j), x(1, j), x(2, j));
  return s;
}

/// Runs `body` with the usual handling: input errors exit 1 with the message.
template <class Body>
void guarded(int& exit_code, Body body) {
  try {
    body();
  } catch (const Error& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    exit_code = kExitInputError;
  }
}

void run_probe(const Args& a) {
  const Scenario s = load_scenario(a.scenario);
  print_notes(s);
  if (s.markers.embedded.empty())
    throw Error(fmt::format("{}: probe needs markers (markers.rest) to report", s.path));
  ProbeExperiment ex(s, load_probing(s));
  std::unique_ptr<Blender> blender;
  if (!a.blend.empty()) {
    blender = std::make_unique<Blender>(s.mesh, read_sets(a.blend, ex.model(0)), blend_options(a));
    std::string names;
    for (const auto& set : blender->sets()) names += (names.empty() ? "" : ", ") + set.name;
    fmt::print("blending {} parameter sets ({}) by the {} strain metric\n", blender->sets().size(),
               names, a.metric);
  }
  if (const std::string why = prepare_output_dir(a.outdir); !why.empty()) throw Error(why);
  std::string reactions = "measurement,press,fx,fy,fz\n";
  bool pressed = false;
  for (int m = 0; m < ex.size(); ++m) {
    Eigen::Matrix3Xd x;
    if (blender) {
      const BlendedEquilibrium b = blended_equilibrium(ex.model(m), *blender);
      if (b.x.size() == 0)
        throw Error(fmt::format("measurement '{}' with the blended sets: {}",
                                ex.spec().measurements[m].name, b.message));
      std::string mix;
      const Eigen::VectorXd mean = b.weights.rowwise().mean();
      for (int k = 0; k < mean.size(); ++k)
        mix += fmt::format("{}{} {:.2f}", k ? ", " : "", blender->sets()[k].name, mean[k]);
      fmt::print("{}: mean weights {}; {} passes at the full load{}\n",
                 ex.spec().measurements[m].name, mix, b.passes,
                 b.converged ? "" : " (" + b.message + ")");
      x = b.x;
    } else {
      x = ex.equilibrium(m);
    }
    const Eigen::Matrix3Xd at = marker_positions(s.mesh, s.markers.embedded, x);
    const Eigen::Matrix3Xd rest = marker_positions(s.mesh, s.markers.embedded, s.mesh.nodes);
    const std::string name = ex.spec().measurements[m].name;
    const std::string path = (std::filesystem::path(a.outdir) / (name + ".csv")).string();
    write_file_atomic(path, positions_csv(s.markers.embedded, at));
    fmt::print(
        "{}: largest marker displacement {:.3f} mm, largest node displacement {:.3f} mm; "
        "wrote {}\n",
        name, 1e3 * (at - rest).colwise().norm().maxCoeff(),
        1e3 * (x - s.mesh.nodes).colwise().norm().maxCoeff(), path);
    const auto& presses = ex.spec().measurements[m].presses;
    const std::vector<Eigen::Vector3d> R = ex.reactions(m, x);
    for (size_t k = 0; k < R.size(); ++k) {
      pressed = true;
      reactions += fmt::format("{},{},{:.9g},{:.9g},{:.9g}\n", name, presses[k].clamp.name,
                               R[k].x(), R[k].y(), R[k].z());
      fmt::print("  press '{}': force on the body [{:.6g}, {:.6g}, {:.6g}] N\n",
                 presses[k].clamp.name, R[k].x(), R[k].y(), R[k].z());
    }
  }
  if (pressed) {
    const std::string path = (std::filesystem::path(a.outdir) / "reactions.csv").string();
    write_file_atomic(path, reactions);
    fmt::print("wrote {}\n", path);
  }
}

std::string fields_csv(const std::vector<std::string>& names, const Eigen::MatrixXd& q) {
  std::string s = "element";
  for (const auto& n : names) s += ",elastic." + n;
  s += "\n";
  for (int e = 0; e < q.cols(); ++e) {
    s += std::to_string(e);
    for (int k = 0; k < q.rows(); ++k) s += fmt::format(",{:.9g}", q(k, e));
    s += "\n";
  }
  return s;
}

/// One line per distinct fitted value set (global and region fits), or the range
/// over the elements.
void print_values(const std::vector<std::string>& names, const Eigen::MatrixXd& q,
                  const std::vector<int>& group, int groups) {
  const auto lambda = std::find(names.begin(), names.end(), "lambda") - names.begin();
  const auto mu = std::find(names.begin(), names.end(), "mu") - names.begin();
  const bool lame =
      lambda < static_cast<long>(names.size()) && mu < static_cast<long>(names.size());
  auto line = [&](const std::string& what, const Eigen::VectorXd& v) {
    std::string s = "  " + what + ":";
    for (size_t k = 0; k < names.size(); ++k) s += fmt::format(" {} {:.5g}", names[k], v[k]);
    if (lame)
      s += fmt::format("  (E {:.5g} Pa, Poisson's ratio {:.4f})", youngs_modulus(v[lambda], v[mu]),
                       poissons_ratio(v[lambda], v[mu]));
    fmt::print("{}\n", s);
  };
  if (groups <= 16) {
    for (int g = 0; g < groups; ++g) {
      const int e = static_cast<int>(std::find(group.begin(), group.end(), g) - group.begin());
      line(groups == 1 ? "fitted" : fmt::format("group {}", g), q.col(e));
    }
    return;
  }
  for (size_t k = 0; k < names.size(); ++k) {
    Eigen::VectorXd v = q.row(k).transpose();
    std::sort(v.data(), v.data() + v.size());
    fmt::print("  {} over {} elements: min {:.4g}, median {:.4g}, max {:.4g}\n", names[k], v.size(),
               v[0], v[v.size() / 2], v[v.size() - 1]);
  }
}

void run_probe_fit(const Args& a) {
  const Scenario s = load_scenario(a.scenario);
  print_notes(s);
  ProbingSpec spec = load_probing(s);
  if (!a.method.empty()) spec.method = a.method;
  if (!a.grouping.empty())
    spec.grouping = a.grouping == "global"   ? ElementGrouping::kGlobal
                    : a.grouping == "region" ? ElementGrouping::kRegion
                                             : ElementGrouping::kElement;
  if (a.gamma >= 0) spec.gamma = a.gamma;
  if (a.cross_validate && spec.method != "displacement")
    throw Error("--cross-validate fits with the displacement-based inverse (method: displacement)");
  for (const auto& m : spec.measurements)
    if (m.observed_path.empty())
      throw Error(fmt::format("{}: measurement '{}' has no observed positions (observed: file)",
                              s.path, m.name));
  ProbeExperiment ex(s, spec);
  bool forced = false;  // does any known force set the moduli's scale?
  for (const auto& l : s.loads) forced |= l.force.norm() > 0 || l.mass > 0;
  for (int m = 0; m < ex.size(); ++m) {
    forced |= !ex.measured_reactions(m).empty();
    for (const auto& l : spec.measurements[m].loads) forced |= l.force.norm() > 0 || l.mass > 0;
  }
  if (!forced)
    fmt::print("note: no load has a force or mass and no press a measured reaction: {}\n",
               s.gravity.norm() > 0
                   ? "only the body's own weight sets the moduli's scale"
                   : "nothing sets the moduli's scale (no gravity either); only their "
                     "ratios are fitted");
  if (const std::string why = prepare_output_dir(a.outdir); !why.empty()) throw Error(why);
  std::vector<std::string> names;
  Eigen::MatrixXd q;
  fmt::print("{} measurements, {} inverse\n", ex.size(), spec.method);
  if (spec.method == "force") {
    ForceInverseOptions o;
    o.grouping = spec.grouping;
    o.gamma_space = spec.gamma;
    const ForceInverseResult r = force_based_inverse(ex.node_positions(), o);
    names = r.parameters, q = r.q[0];
    if (!r.lcurve.empty()) {
      std::string csv = "gamma,residual_N,roughness\n";
      for (const auto& p : r.lcurve)
        csv += fmt::format("{:.6g},{:.9g},{:.9g}\n", p.gamma, p.residual, p.roughness);
      write_file_atomic((std::filesystem::path(a.outdir) / "lcurve.csv").string(), csv);
      fmt::print("  γ {:.3g} from the L-curve's corner ({} values; lcurve.csv)\n", r.gamma_space,
                 r.lcurve.size());
    }
    fmt::print("  relative force residual {:.4g}\n", r.relative_residual);
  } else {
    DisplacementInverseOptions o;
    o.grouping = spec.grouping;
    o.gamma_space = std::max(spec.gamma, 0.0);
    std::vector<ObservedProbe> probes = ex.observed();
    const DisplacementInverseResult r = displacement_based_inverse(probes, o);
    names = r.parameters, q = r.q;
    fmt::print("  marker rms {:.4f} mm per coordinate after {} evaluations ({})\n", 1e3 * r.rms,
               r.evaluations, r.stop);
    if (spec.reaction_weight() > 0)
      fmt::print("  measured reactions: rms {:.4g} N per component\n", r.reaction_rms);
  }
  const auto [group, groups] = element_groups(s.mesh, spec.grouping);
  print_values(names, q, group, groups);
  const std::string path = (std::filesystem::path(a.outdir) / "fitted-fields.csv").string();
  write_file_atomic(path, fields_csv(names, q));
  fmt::print("wrote {} (material.fields)\n", path);

  std::vector<std::string> measurement_names;
  for (const auto& m : spec.measurements) measurement_names.push_back(m.name);
  DisplacementInverseOptions o;
  o.grouping = spec.grouping;
  o.gamma_space = std::max(spec.gamma, 0.0);
  if (a.sets) {
    // From the scenario's start values, like the fit above.
    ProbeExperiment fresh(s, spec);
    std::vector<ParameterSet> sets;
    if (spec.method == "force") {
      ForceInverseOptions fo;
      fo.grouping = spec.grouping;
      fo.gamma_space = spec.gamma;
      fo.gamma_measurement = spec.gamma_measurements;
      sets = force_parameter_sets(fresh.node_positions(), measurement_names, fo);
    } else {
      std::vector<ObservedProbe> probes = fresh.observed();
      sets = fit_parameter_sets(probes, measurement_names, o);
    }
    const std::filesystem::path dir = std::filesystem::path(a.outdir) / "sets";
    std::filesystem::create_directories(dir);
    // probe --blend reads every set here: ones of an earlier run would join the blend.
    for (const auto& entry : std::filesystem::directory_iterator(dir))
      if (entry.path().extension() == ".csv") std::filesystem::remove(entry.path());
    fmt::print("one parameter set per measurement (kelvin probe --blend {}):\n", a.outdir);
    for (const auto& set : sets) {
      write_file_atomic((dir / (set.name + ".csv")).string(), parameter_set_csv(names, set));
      print_values(names, set.q, group, groups);
      fmt::print("    ({}: strain level {:.4f})\n", set.name, strain_level(s.mesh, set.strain));
    }
  }
  if (a.cross_validate) {
    ProbeExperiment fresh(s, spec);
    std::vector<ObservedProbe> probes = fresh.observed();
    BlendOptions global = blend_options(a), local = blend_options(a);
    global.metric = BlendMetric::kGlobal, local.metric = BlendMetric::kLocal;
    fmt::print("leave-one-out: each measurement predicted from the others (marker rms, mm)\n");
    const auto folds = cross_validate_blending(probes, measurement_names, o, {global, local});
    std::string csv = "held_out,one_set_mm,blended_strain_level_mm,blended_local_mm\n";
    fmt::print("  {:<16} {:>10} {:>14} {:>12}\n", "held out", "one set", "blended level",
               "blended local");
    double sum[3] = {0, 0, 0};
    for (const auto& f : folds) {
      const double r[3] = {f.single_rms, f.blended[0].rms, f.blended[1].rms};
      fmt::print("  {:<16} {:>10.4f} {:>14.4f} {:>12.4f}{}\n", f.held_out, 1e3 * r[0], 1e3 * r[1],
                 1e3 * r[2],
                 f.blended[0].converged && f.blended[1].converged ? "" : "  (weights not settled)");
      csv +=
          fmt::format("{},{:.6g},{:.6g},{:.6g}\n", f.held_out, 1e3 * r[0], 1e3 * r[1], 1e3 * r[2]);
      for (int k = 0; k < 3; ++k) sum[k] += r[k] * r[k];
    }
    const double n = static_cast<double>(folds.size());
    fmt::print("  {:<16} {:>10.4f} {:>14.4f} {:>12.4f}\n", "all", 1e3 * std::sqrt(sum[0] / n),
               1e3 * std::sqrt(sum[1] / n), 1e3 * std::sqrt(sum[2] / n));
    write_file_atomic((std::filesystem::path(a.outdir) / "cross-validation.csv").string(), csv);
  }
}

}  // namespace

void register_probe(CLI::App& app, int& exit_code) {
  auto a = std::make_shared<Args>();
  CLI::App* sim = app.add_subcommand(
      "probe",
      "Simulate the static measurements of a scenario's `probing:` section: each one's "
      "equilibrium under its loads, and the markers' loaded positions (OUTDIR/<name>.csv).");
  sim->add_option("scenario", a->scenario, "scenario YAML with a probing: section")->required();
  sim->add_option("-o,--outdir", a->outdir, "output directory")->capture_default_str();
  sim->add_option("--blend", a->blend,
                  "a kelvin probe-fit --sets output directory: simulate with its parameter sets "
                  "blended in strain space (Bächer 2008, ch. 6)");
  sim->add_option("--metric", a->metric,
                  "of the blend: global (the body's strain level; a homogeneous body) or local "
                  "(each element's neighbourhood; an inhomogeneous one)")
      ->check(CLI::IsMember({"global", "local"}))
      ->capture_default_str();
  sim->add_option("--radius", a->radius,
                  "the local metric's radius in space (m); default twice the element size")
      ->check(positive_number(false));
  sim->callback([a, &exit_code] { guarded(exit_code, [&] { run_probe(*a); }); });

  CLI::App* fit = app.add_subcommand(
      "probe-fit",
      "Fit the elastic parameters to static probing measurements (Bächer 2008): "
      "displacement-based (marker misfit, adjoint of the equilibrium) or force-based (linear "
      "least squares on SuiteSparseQR, every node observed); writes OUTDIR/fitted-fields.csv.");
  fit->add_option("scenario", a->scenario, "scenario YAML with a probing: section")->required();
  fit->add_option("-o,--outdir", a->outdir, "output directory")->capture_default_str();
  fit->add_option("--method", a->method, "displacement or force (default: the scenario's)")
      ->check(CLI::IsMember({"displacement", "force"}));
  fit->add_option("--grouping", a->grouping, "global, region or element (default: the scenario's)")
      ->check(CLI::IsMember({"global", "region", "element"}));
  fit->add_option("--gamma", a->gamma, "smoothness across element faces (relative)")
      ->check(positive_number(true));
  fit->add_flag("--sets", a->sets,
                "also fit one parameter set per measurement (OUTDIR/sets/), for kelvin probe "
                "--blend");
  fit->add_flag("--cross-validate", a->cross_validate,
                "leave each measurement out in turn: predict it from one set fitted to the "
                "others and from their per-measurement sets blended (OUTDIR/cross-validation.csv)");
  fit->callback([a, &exit_code] { guarded(exit_code, [&] { run_probe_fit(*a); }); });
}

}  // namespace kelvin
