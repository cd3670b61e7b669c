#include "fit/fit_report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <limits>
#include <map>

#include "engine/output.hpp"
#include "fit/svg_plot.hpp"

namespace kelvin {

namespace {

namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
/// Beyond this a per-element fit's table would bury the summary; the rest is summarised
/// (every value is in fitted.yaml and parameters.pvd).
constexpr std::size_t kMaxParameterRows = 40;
constexpr std::size_t kMaxMarkerRows = 30;

constexpr const char* kBlue = "#1f77b4";
constexpr const char* kOrange = "#ff7f0e";
constexpr const char* kGrey = "#9e9e9e";
constexpr const char* kDark = "#333333";

template <typename... Args>
void emit(std::string& out, fmt::format_string<Args...> format, Args&&... args) {
  fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
}

/// Entry j of an optional vector (NaN when absent), so a partly filled FitReportData
/// still gives a report.
double at(const Eigen::VectorXd& v, std::size_t j) {
  return j < static_cast<std::size_t>(v.size()) ? v[static_cast<Eigen::Index>(j)] : kNaN;
}

/// A number for a table: 4 significant digits; unbounded as ∞, missing as —.
std::string num(double v, int digits = 4) {
  if (std::isnan(v)) return "—";
  if (std::isinf(v)) return v > 0 ? "∞" : "−∞";
  return fmt::format("{:.{}g}", v, digits);
}

/// A length given in metres, shown in millimetres.
std::string mm(double metres) {
  return num(metres * 1e3, 3);
}

std::string percent_change(double before, double after) {
  if (!(before > 0) || !std::isfinite(after)) return "—";
  return fmt::format("{:+.1f} %", 100 * (after - before) / before);
}

std::string duration(double seconds) {
  if (seconds < 60) return fmt::format("{:.1f} s", seconds);
  const long s = std::lround(seconds);
  if (s < 3600) return fmt::format("{} min {:02} s", s / 60, s % 60);
  return fmt::format("{} h {:02} min", s / 3600, (s % 3600) / 60);
}

/// Table cells may not contain '|' or line breaks.
std::string cell(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '|')
      out += "\\|";
    else
      out += c == '\n' ? ' ' : c;
  }
  return out;
}

double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  const auto mid = v.begin() + static_cast<long>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

bool rms_known(const FitReportData& d) {
  return !d.markers.empty() || !d.targets.empty() || d.rms_before > 0 || d.rms_after > 0;
}

// ---------------------------------------------------------------- report.md sections

std::string summary_section(const FitReportData& d) {
  std::string out = fmt::format("# Fit report: {}\n\n", d.title);
  if (!d.scenario_path.empty()) emit(out, "Scenario: `{}`\n\n", d.scenario_path);
  if (rms_known(d))
    emit(out, "**{} RMS {} mm → {} mm** ({}) · ",
         d.targets.empty()   ? "Marker"
         : d.markers.empty() ? "Shape-target"
                             : "Marker and target",
         mm(d.rms_before), mm(d.rms_after), percent_change(d.rms_before, d.rms_after));
  else
    out += "**Marker RMS not evaluated** · ";
  emit(out, "{} evaluations, {} failed · {} · {}", d.evaluations, d.failures, duration(d.seconds),
       d.algorithm.empty() ? "unknown algorithm" : d.algorithm);
  if (!d.gradient_method.empty()) emit(out, " ({} gradients)", d.gradient_method);
  emit(out, " · {}\n\n", d.stop_reason.empty() ? "—" : d.stop_reason);
  out += d.interrupted
             ? "> **Interrupted.** The fit did not finish; the fitted values are the best found "
               "so far.\n\n"
             : "The run finished without interruption.\n\n";
  return out;
}

/// "at lower bound" when the optimiser ended on a bound: the bound, not the data,
/// decided that value.
std::string bound_note(double fitted, double lower, double upper) {
  const auto near = [&](double bound) {
    return std::isfinite(bound) &&
           std::abs(fitted - bound) <= 1e-6 * std::max(1.0, std::abs(bound));
  };
  if (near(lower)) return "at lower bound";
  if (near(upper)) return "at upper bound";
  return "";
}

std::string std_error_cell(double fitted, double error) {
  if (std::isnan(error)) return "—";
  if (fitted == 0 || !std::isfinite(fitted)) return fmt::format("± {}", num(error, 3));
  return fmt::format("± {} ({:.1f} %)", num(error, 3), 100 * error / std::abs(fitted));
}

std::string parameter_row(const FitReportData& d, std::size_t j, bool with_error) {
  const double start = at(d.initial, j), fitted = at(d.fitted, j);
  const double lower = at(d.lower, j), upper = at(d.upper, j);
  std::string row = fmt::format("| {} | {} | {} |", cell(d.labels[j]), num(start), num(fitted));
  if (with_error) emit(row, " {} |", std_error_cell(fitted, at(d.std_error, j)));
  emit(row, " [{}, {}] | {} | {} |\n", num(lower), num(upper),
       start != 0 ? num(fitted / start, 3) : "—", bound_note(fitted, lower, upper));
  return row;
}

/// Label up to its first '[': the field a per-element entry belongs to.
std::string label_group(const std::string& label) {
  return label.substr(0, label.find('['));
}

/// Count and spread of the fitted values of rows [first, end), per field.
std::string omitted_parameters(const FitReportData& d, std::size_t first) {
  std::map<std::string, std::vector<double>> groups;
  for (std::size_t j = first; j < d.labels.size(); ++j)
    groups[label_group(d.labels[j])].push_back(at(d.fitted, j));
  std::string out = fmt::format(
      "\n{} further entries are not listed (all are in the fitted scenario). Their fitted "
      "values:\n\n| field | entries | min | median | max |\n|---|---:|---:|---:|---:|\n",
      d.labels.size() - first);
  for (const auto& [name, v] : groups)
    emit(out, "| {} | {} | {} | {} | {} |\n", cell(name), v.size(),
         num(*std::min_element(v.begin(), v.end())), num(median(v)),
         num(*std::max_element(v.begin(), v.end())));
  return out;
}

std::string parameter_section(const FitReportData& d) {
  if (d.labels.empty()) return "";
  const bool with_error = d.std_error.size() > 0;
  std::string out = "## Parameters\n\nModel units.";
  if (with_error)
    out +=
        " Standard errors from the Gauss–Newton approximation at the fit (linearised, "
        "assuming independent marker noise).";
  out += with_error
             ? "\n\n| parameter | start | fitted | std. error | bounds | fitted/start | note |\n"
               "|---|---:|---:|---:|---|---:|---|\n"
             : "\n\n| parameter | start | fitted | bounds | fitted/start | note |\n"
               "|---|---:|---:|---|---:|---|\n";
  const std::size_t shown = std::min(d.labels.size(), kMaxParameterRows);
  for (std::size_t j = 0; j < shown; ++j) out += parameter_row(d, j, with_error);
  if (shown < d.labels.size()) out += omitted_parameters(d, shown);
  if (d.noise_sigma > 0)
    emit(out,
         "\nEstimated marker noise σ = {} mm per coordinate (from the residual at the fit; a "
         "3-D RMS after the fit of about σ·√3 means the model explains the data to within the "
         "noise).\n",
         mm(d.noise_sigma));
  return out + "\n";
}

/// Worst first after the fit; markers whose simulation failed (NaN) come first of all.
std::vector<MarkerRms> worst_first(std::vector<MarkerRms> markers) {
  const auto key = [](const MarkerRms& m) {
    return std::isnan(m.after) ? std::numeric_limits<double>::infinity() : m.after;
  };
  std::stable_sort(markers.begin(), markers.end(),
                   [&](const MarkerRms& a, const MarkerRms& b) { return key(a) > key(b); });
  return markers;
}

std::string marker_section(const FitReportData& d) {
  if (d.markers.empty()) return "";
  const auto sorted = worst_first(d.markers);
  std::string out =
      "## Markers\n\nRMS distance between observed and simulated positions, worst first.\n\n"
      "| experiment | marker | before (mm) | after (mm) | change |\n|---|---|---:|---:|---:|\n";
  const std::size_t shown = std::min(sorted.size(), kMaxMarkerRows);
  for (std::size_t i = 0; i < shown; ++i) {
    const auto& m = sorted[i];
    emit(out, "| {} | {} | {} | {} | {} |\n", cell(m.experiment), cell(m.marker), mm(m.before),
         mm(m.after), percent_change(m.before, m.after));
  }
  if (shown < sorted.size())
    emit(out, "\n{} more markers not listed, each with RMS after ≤ {} mm.\n", sorted.size() - shown,
         mm(sorted[shown].after));
  return out + "\n";
}

std::string target_section(const FitReportData& d) {
  if (d.targets.empty()) return "";
  std::string out =
      "## Shape targets\n\nRMS distance between the target shape and the simulated one at the "
      "target's time, over the coordinates that count.\n\n"
      "| experiment | target | time (s) | coordinates | before (mm) | after (mm) | change "
      "|\n|---|---|---:|---:|---:|---:|---:|\n";
  for (const auto& t : d.targets)
    emit(out, "| {} | {} | {} | {} | {} | {} | {} |\n", cell(t.experiment), cell(t.target),
         num(t.time, 4), t.coordinates, mm(t.before), mm(t.after),
         percent_change(t.before, t.after));
  return out + "\n";
}

std::string lcurve_section(const std::vector<LcurvePoint>& lcurve) {
  std::string out =
      "## L-curve\n\nOne fit per smoothness weight γ. The corner of the curve balances the "
      "data fit against the roughness of the fitted fields.\n\n![L-curve](lcurve.svg)\n\n"
      "| γ | misfit Φ | roughness | RMS (mm) | evaluations |\n|---:|---:|---:|---:|---:|\n";
  for (const auto& p : lcurve)
    emit(out, "| {} | {} | {} | {} | {} |\n", num(p.gamma, 3), num(p.misfit), num(p.roughness),
         mm(p.rms), p.evaluations);
  return out + "\n";
}

std::string files_section(const std::vector<std::string>& files) {
  std::string out = "## Files\n\n";
  for (const auto& f : files) emit(out, "- [{0}]({0})\n", f);
  return out;
}

// ---------------------------------------------------------------- plots

/// Every successful evaluation as a dot, the best-so-far (the accepted iterates) as a
/// line, and failures as vertical marks: their objective (kFailedObjective) is not data.
svg::Plot objective_plot(const std::vector<FitRecord>& history) {
  svg::Series all{"every evaluation", {}, {}, kGrey, false, svg::Style::markers, {}};
  svg::Series best{"best objective", {}, {}, kBlue, false, svg::Style::line_and_markers, {}};
  svg::Series misfit{"misfit Φ at best", {}, {}, kOrange, true, svg::Style::line, {}};
  svg::Plot plot;
  plot.title = "Objective over evaluations";
  plot.x_label = "evaluation";
  plot.y_label = "objective (misfit + penalty)";
  plot.log_y = true;
  plot.x_marks_name = "failed evaluation";
  bool penalised = false;
  double lowest = std::numeric_limits<double>::infinity();
  for (const auto& r : history) {
    if (!r.ok || r.objective >= kFailedObjective) {
      plot.x_marks.push_back(r.evaluation);
      continue;
    }
    all.x.push_back(r.evaluation);
    all.y.push_back(r.objective);
    penalised |= r.penalty != 0;
    if (r.objective < lowest) {
      lowest = r.objective;
      best.x.push_back(r.evaluation);
      best.y.push_back(r.objective);
      misfit.x.push_back(r.evaluation);
      misfit.y.push_back(r.misfit);
    }
  }
  plot.series = {all, best};
  if (penalised) plot.series.push_back(misfit);  // else it coincides with the objective
  return plot;
}

/// Column of the first frame where component c was observed (the displacement origin).
Eigen::Index first_observed(const TrackPlot& t, int c, Eigen::Index frames) {
  for (Eigen::Index f = 0; f < frames; ++f)
    if (std::isfinite(t.observed(c, f))) return f;
  return -1;
}

/// Component c of `positions` minus `origin`, in mm; NaN stays NaN (a gap in the plot).
std::vector<double> displacement_mm(const Eigen::Matrix3Xd& positions, int c, double origin,
                                    Eigen::Index frames) {
  std::vector<double> out(static_cast<std::size_t>(frames), kNaN);
  for (Eigen::Index f = 0; f < std::min(frames, positions.cols()); ++f)
    out[static_cast<std::size_t>(f)] = (positions(c, f) - origin) * 1e3;
  return out;
}

/// x, y and z panels of one marker. Displacements are taken relative to the first observed
/// position for all three curves, so an offset between simulation and capture stays visible.
svg::Figure track_figure(const TrackPlot& t) {
  svg::Figure figure;
  figure.title = fmt::format("Marker {} ({}): RMS {} mm → {} mm", t.marker, t.experiment,
                             mm(t.rms_before), mm(t.rms_after));
  const Eigen::Index frames =
      std::min<Eigen::Index>(static_cast<Eigen::Index>(t.t.size()), t.observed.cols());
  const char* axes[] = {"x", "y", "z"};
  for (int c = 0; c < 3; ++c) {
    const Eigen::Index f0 = first_observed(t, c, frames);
    const double origin = f0 < 0 ? 0 : t.observed(c, f0);
    const std::vector<double> time(t.t.begin(), t.t.begin() + frames);
    svg::Plot panel;
    panel.x_label = "time (s)";
    panel.y_label =
        f0 < 0 ? fmt::format("{} (mm)", axes[c]) : fmt::format("{0} − {0}₀ (mm)", axes[c]);
    panel.series = {
        {"observed",
         time,
         displacement_mm(t.observed, c, origin, frames),
         kDark,
         false,
         svg::Style::markers,
         {}},
        {"start parameters",
         time,
         displacement_mm(t.before, c, origin, frames),
         kOrange,
         true,
         svg::Style::line,
         {}},
        {"fitted parameters",
         time,
         displacement_mm(t.after, c, origin, frames),
         kBlue,
         false,
         svg::Style::line,
         {}},
    };
    figure.panels.push_back(std::move(panel));
  }
  return figure;
}

svg::Plot lcurve_plot(const std::vector<LcurvePoint>& lcurve) {
  svg::Series curve{"fits", {}, {}, kBlue, false, svg::Style::line_and_markers, {}};
  for (const auto& p : lcurve) {
    curve.x.push_back(p.misfit);
    curve.y.push_back(p.roughness);
    curve.labels.push_back(fmt::format("γ={}", num(p.gamma, 3)));
  }
  svg::Plot plot;
  plot.title = "L-curve";
  plot.x_label = "misfit Φ";
  plot.y_label = "roughness Σ(p_a − p_b)²";
  plot.log_x = plot.log_y = true;
  plot.series = {curve};
  return plot;
}

std::string track_heading(const TrackPlot& t) {
  return fmt::format("### Marker {} ({}): {} mm → {} mm\n\n", t.marker, t.experiment,
                     mm(t.rms_before), mm(t.rms_after));
}

}  // namespace

std::string write_fit_report(const std::string& outdir, const FitReportData& data) {
  fs::create_directories(outdir);
  std::vector<std::string> written;
  const auto write = [&](const std::string& name, const std::string& contents) {
    write_file_atomic((fs::path(outdir) / name).string(), contents);
    written.push_back(name);
  };

  std::string md =
      summary_section(data) + parameter_section(data) + marker_section(data) + target_section(data);
  if (!data.history.empty()) {
    write("objective.svg", svg::render(objective_plot(data.history)));
    md += "## Objective\n\n![objective over evaluations](objective.svg)\n\n";
  }
  if (!data.tracks.empty()) {
    md +=
        "## Tracks\n\nDisplacement relative to the first observed position: observed (dots), "
        "simulated with the start parameters (dashed) and the fitted ones (solid).\n\n";
    for (std::size_t k = 0; k < data.tracks.size(); ++k) {
      const std::string name = fmt::format("track-{}.svg", k + 1);
      write(name, svg::render(track_figure(data.tracks[k])));
      md += track_heading(data.tracks[k]) +
            fmt::format("![marker {}]({})\n\n", data.tracks[k].marker, name);
    }
  }
  if (!data.lcurve.empty()) {
    write("lcurve.svg", svg::render(lcurve_plot(data.lcurve)));
    md += lcurve_section(data.lcurve);
  }
  for (const auto& section : data.extra_sections) md += section + "\n";

  std::vector<std::string> files{"report.md"};
  files.insert(files.end(), written.begin(), written.end());
  files.insert(files.end(), data.files.begin(), data.files.end());
  md += files_section(files);
  const std::string path = (fs::path(outdir) / "report.md").string();
  write_file_atomic(path, md);
  return path;
}

}  // namespace kelvin
