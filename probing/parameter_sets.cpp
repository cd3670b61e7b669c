#include "probing/parameter_sets.hpp"

#include <fmt/format.h>

#include <cmath>

#include "base/error.hpp"
#include "engine/csv.hpp"
#include "probing/probing_system.hpp"

namespace kelvin {
namespace {

const char* const kStrainColumns[6] = {"strain.E11", "strain.E22", "strain.E33",
                                       "strain.E23", "strain.E13", "strain.E12"};

}  // namespace

double marker_rms(const ObservedProbe& probe, const Eigen::Matrix3Xd& x) {
  const Eigen::Matrix3Xd at = marker_positions(probe.model->mesh(), probe.markers, x);
  double sum = 0;
  int seen = 0;
  for (int j = 0; j < at.cols(); ++j)
    if (probe.observed.col(j).allFinite())
      sum += (at.col(j) - probe.observed.col(j)).squaredNorm(), ++seen;
  return seen ? std::sqrt(sum / (3.0 * seen)) : NAN;
}

std::vector<ParameterSet> fit_parameter_sets(std::vector<ObservedProbe>& measurements,
                                             const std::vector<std::string>& names,
                                             const DisplacementInverseOptions& options) {
  std::vector<ParameterSet> sets;
  for (size_t m = 0; m < measurements.size(); ++m) {
    std::vector<ObservedProbe> one{measurements[m]};
    const DisplacementInverseResult r = displacement_based_inverse(one, options);
    const Eigen::Matrix3Xd x = static_equilibrium(*measurements[m].model, names[m]);
    sets.push_back({names[m], r.q, element_strains(measurements[m].model->mesh(), x)});
  }
  return sets;
}

std::vector<ParameterSet> force_parameter_sets(const std::vector<StaticState>& measurements,
                                               const std::vector<std::string>& names,
                                               ForceInverseOptions options) {
  options.per_measurement = true;
  const ForceInverseResult r = force_based_inverse(measurements, options);
  std::vector<ParameterSet> sets;
  for (size_t m = 0; m < measurements.size(); ++m)
    sets.push_back(
        {names[m], r.q[m], element_strains(measurements[m].model->mesh(), measurements[m].x)});
  return sets;
}

std::string parameter_set_csv(const std::vector<std::string>& parameters, const ParameterSet& set) {
  std::string s = "element";
  for (const auto& p : parameters) s += ",elastic." + p;
  for (const char* c : kStrainColumns) s += std::string(",") + c;
  s += "\n";
  for (int e = 0; e < set.q.cols(); ++e) {
    s += std::to_string(e);
    for (int k = 0; k < set.q.rows(); ++k) s += fmt::format(",{:.17g}", set.q(k, e));
    for (int k = 0; k < 6; ++k) s += fmt::format(",{:.17g}", set.strain(k, e));
    s += "\n";
  }
  return s;
}

ParameterSet read_parameter_set(const std::string& path, const std::string& name,
                                const std::vector<std::string>& parameters, int elements) {
  const auto lines = read_csv_lines(path);
  if (lines.empty()) throw Error(fmt::format("{}: empty parameter set", path));
  std::vector<std::string> want{"element"};
  for (const auto& p : parameters) want.push_back("elastic." + p);
  for (const char* c : kStrainColumns) want.push_back(c);
  const auto header = split_csv_line(lines[0].second);
  if (header != want) {
    std::string w;
    for (const auto& c : want) w += (w.empty() ? "" : ",") + c;
    throw Error(fmt::format("{}:{}: the header must be {} (the set of this scenario's material)",
                            path, lines[0].first, w));
  }
  const int nq = static_cast<int>(parameters.size());
  ParameterSet set{name, Eigen::MatrixXd::Constant(nq, elements, NAN),
                   Eigen::MatrixXd::Constant(6, elements, NAN)};
  for (size_t i = 1; i < lines.size(); ++i) {
    const auto& [line, text] = lines[i];
    const auto cells = split_csv_line(text);
    if (cells.size() != want.size())
      throw Error(
          fmt::format("{}:{}: {} cells, expected {}", path, line, cells.size(), want.size()));
    std::vector<double> v(cells.size());
    for (size_t c = 0; c < cells.size(); ++c)
      if (!parse_csv_number(cells[c], v[c]) || !std::isfinite(v[c]))
        throw Error(
            fmt::format("{}:{}: {}: '{}' is not a finite number", path, line, want[c], cells[c]));
    const double e = v[0];
    if (e != std::floor(e) || e < 0 || e >= elements)
      throw Error(fmt::format("{}:{}: element: {} is not an element of the mesh (0 … {})", path,
                              line, cells[0], elements - 1));
    const int el = static_cast<int>(e);
    if (!std::isnan(set.q(0, el)))
      throw Error(fmt::format("{}:{}: element {} appears twice", path, line, el));
    for (int k = 0; k < nq; ++k) {
      if (!(v[1 + k] > 0))
        throw Error(fmt::format("{}:{}: {}: must be > 0", path, line, want[1 + k]));
      set.q(k, el) = v[1 + k];
    }
    for (int k = 0; k < 6; ++k) set.strain(k, el) = v[1 + nq + k];
  }
  for (int e = 0; e < elements; ++e)
    if (std::isnan(set.q(0, e)))
      throw Error(fmt::format("{}: element {} has no row (the set must cover the mesh)", path, e));
  return set;
}

std::vector<CrossValidationFold> cross_validate_blending(std::vector<ObservedProbe>& measurements,
                                                         const std::vector<std::string>& names,
                                                         const DisplacementInverseOptions& fit,
                                                         const std::vector<BlendOptions>& blends) {
  const int n = static_cast<int>(measurements.size());
  if (n < 3)
    throw Error(fmt::format(
        "cross-validation of blending needs at least 3 measurements (it blends the other ones); "
        "this has {}",
        n));
  const int term = elastic_term(*measurements[0].model);
  std::vector<Eigen::MatrixXd> start;
  for (auto& m : measurements) start.push_back(m.model->terms()[term].q);
  auto restart = [&] {
    for (int m = 0; m < n; ++m) measurements[m].model->terms()[term].q = start[m];
  };
  std::vector<CrossValidationFold> folds;
  for (int k = 0; k < n; ++k) {
    std::vector<ObservedProbe> rest;
    std::vector<std::string> rest_names;
    for (int m = 0; m < n; ++m)
      if (m != k) rest.push_back(measurements[m]), rest_names.push_back(names[m]);
    CrossValidationFold fold;
    fold.held_out = names[k];
    FemModel& held = *measurements[k].model;

    restart();
    const DisplacementInverseResult single = displacement_based_inverse(rest, fit);
    held.terms()[term].q = single.q;
    fold.single_rms = marker_rms(measurements[k], static_equilibrium(held, names[k]));

    restart();
    const std::vector<ParameterSet> sets = fit_parameter_sets(rest, rest_names, fit);
    for (const BlendOptions& blend : blends) {
      const BlendedEquilibrium b = blended_equilibrium(held, Blender(held.mesh(), sets, blend));
      if (b.x.size() == 0)
        throw Error(fmt::format("measurement '{}' with the blended sets: {}", names[k], b.message));
      fold.blended.push_back({marker_rms(measurements[k], b.x), b.passes, b.converged});
    }
    folds.push_back(fold);
  }
  restart();
  return folds;
}

}  // namespace kelvin
