// `kelvin probe` and `kelvin probe-fit`: static probing (Bächer 2008). `probe`
// simulates each measurement of a scenario's `probing:` section and writes the
// markers' loaded positions; `probe-fit` fits the elastic parameters to measured
// ones with the displacement-based or the force-based inverse.
#include <fmt/format.h>

#include <algorithm>
#include <filesystem>

#include "drivers/commands.hpp"
#include "engine/error.hpp"
#include "engine/output.hpp"
#include "probing/probe_experiment.hpp"

namespace kelvin {
namespace {

struct Args {
  std::string scenario, outdir = "out";
  std::string method, grouping;
  double gamma = -1;
};

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
  if (const std::string why = prepare_output_dir(a.outdir); !why.empty()) throw Error(why);
  for (int m = 0; m < ex.size(); ++m) {
    const Eigen::Matrix3Xd x = ex.equilibrium(m);
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
  for (const auto& m : spec.measurements)
    if (m.observed_path.empty())
      throw Error(fmt::format("{}: measurement '{}' has no observed positions (observed: file)",
                              s.path, m.name));
  ProbeExperiment ex(s, spec);
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
  }
  const auto [group, groups] = element_groups(s.mesh, spec.grouping);
  print_values(names, q, group, groups);
  const std::string path = (std::filesystem::path(a.outdir) / "fitted-fields.csv").string();
  write_file_atomic(path, fields_csv(names, q));
  fmt::print("wrote {} (material.fields)\n", path);
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
  fit->callback([a, &exit_code] { guarded(exit_code, [&] { run_probe_fit(*a); }); });
}

}  // namespace kelvin
