#include "diagnose/diagnosis_outputs.hpp"

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>

#include "engine/output.hpp"
#include "fit/svg_plot.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      out += fmt::format("\\u{:04x}", c);
    } else {
      out += c;
    }
  }
  return out + "\"";
}

std::string json_number(double v) {
  return std::isfinite(v) ? fmt::format("{:.10g}", v) : "null";
}

std::string json_strings(const std::vector<std::string>& v) {
  std::string s = "[";
  for (std::size_t k = 0; k < v.size(); ++k) s += (k ? ", " : "") + json_string(v[k]);
  return s + "]";
}

std::string json_values(const std::vector<NamedValue>& v) {
  std::string s = "[";
  for (std::size_t k = 0; k < v.size(); ++k)
    s += fmt::format("{}{{\"name\": {}, \"value\": {}, \"std_error\": {}}}", k ? ", " : "",
                     json_string(v[k].name), json_number(v[k].value), json_number(v[k].std_error));
  return s + "]";
}

std::string candidate_name(const Diagnosis& d, int c) {
  const Candidate& x = d.candidates[c];
  return x.id == "marker_offset" ? x.id + ":" + x.where : x.id;
}

double heldout_rms(const std::vector<HeldOutFigures>& h, bool after) {
  double sq = 0;
  int n = 0;
  for (const auto& f : h) {
    const MisfitFigures& m = after && f.after.ok ? f.after : f.before;
    sq += m.sum_sq;
    n += m.samples;
  }
  return n ? std::sqrt(sq / n) : NAN;
}

/// Where the field acts, or that none was kept (see fit_missing_force).
std::string where_of(const MissingForce& f) {
  if (f.where.empty())
    return "No field fitted at the first stage's tolerances does better than none at the "
           "scenario's, so none is kept.";
  return fmt::format("Most of it acts in the **{}**, largest at t = {:.3g} s.", f.where,
                     f.peak_time);
}

/// A missing-force field's figures as a JSON object ({"error": …} when not found).
std::string missing_force_json(const MissingForce& f, bool asked) {
  std::string j;
  auto out = std::back_inserter(j);
  if (!f.ok) {
    fmt::format_to(out, "{{\"error\": {}}}", json_string(asked ? f.error : "not asked for"));
    return j;
  }
  fmt::format_to(out,
                 "{{\"where\": {}, \"peak_time\": {}, \"knots\": {}, \"segments\": {}, "
                 "\"evaluations\": {}, \"train_rms_before\": {}, \"train_rms_after\": {}, "
                 "\"statistic\": {}, \"threshold\": {}, \"dof\": {}, \"files\": {}, "
                 "\"regions\": [",
                 json_string(f.where), json_number(f.peak_time), f.knots, f.segments, f.evaluations,
                 json_number(f.rms_before), json_number(f.rms_after), json_number(f.statistic),
                 json_number(f.threshold), f.dof, json_strings(f.files));
  for (std::size_t k = 0; k < f.regions.size(); ++k)
    fmt::format_to(out, "{}{{\"name\": {}, \"rms_force\": {}, \"share\": {}}}", k ? ", " : "",
                   json_string(f.regions[k].name), json_number(f.regions[k].rms_force),
                   json_number(f.regions[k].share));
  j += "]}";
  return j;
}

/// The field's share per region as a Markdown table.
std::string region_table(const MissingForce& f) {
  std::string r = "| region | RMS force density (N/m³) | share of ∫∫\\|f\\|² |\n|---|---:|---:|\n";
  for (const auto& g : f.regions)
    r += fmt::format("| {} | {:.4g} | {:.1f} % |\n", g.name, g.rms_force, 100 * g.share);
  return r;
}

/// The predicted held-out drop of candidate c in mm², empty when not predicted.
std::string heldout_prediction(const Diagnosis& d, int c) {
  if (c < 0 || c >= static_cast<int>(d.predicted_heldout_drop.size()) ||
      !std::isfinite(d.predicted_heldout_drop[c]))
    return "";
  return fmt::format("{:.4g}", d.predicted_heldout_drop[c] * 1e6);
}

/// One refit as a JSON object; its "before" is the model it was added to.
std::string refit_json(const Diagnosis& d, const RefitResult& r) {
  const double before =
      r.on_top_of >= 0 && d.accepted >= 0 ? d.refits[d.accepted].train.rms : d.nominal_train.rms;
  return fmt::format(
      "{{\"candidate\": {}, \"added_to\": {}, \"ok\": {}, \"error\": {}, \"evaluations\": {}, "
      "\"train_rms_before\": {}, \"train_rms_after\": {}, \"statistic\": {}, "
      "\"threshold\": {}, \"dof\": {}, \"bic\": {}, \"heldout_rms_before\": {}, "
      "\"heldout_rms_after\": {}, \"heldout_drop\": {}, \"heldout_threshold\": {}, "
      "\"passes_training\": {}, \"passes_heldout\": {}, \"at_nominal\": {}, \"where\": {}, "
      "\"parameters\": {}, \"nominal_parameters\": {}, \"errors_note\": {}, \"fitted\": {}}}",
      json_string(candidate_name(d, r.candidate)),
      r.on_top_of >= 0 ? json_string(candidate_name(d, r.on_top_of)) : "\"nominal\"",
      r.ok ? "true" : "false", json_string(r.error), r.evaluations, json_number(before),
      json_number(r.train.rms), json_number(r.statistic), json_number(r.threshold), r.dof,
      json_number(r.bic), json_number(heldout_rms(r.heldout, false)),
      json_number(heldout_rms(r.heldout, true)), json_number(r.heldout_drop),
      json_number(r.heldout_threshold), r.passes_training ? "true" : "false",
      r.passes_heldout ? "true" : "false", r.at_nominal ? "true" : "false", json_string(r.where),
      json_values(r.parameters), json_values(r.nominal_parameters), json_string(r.errors_note),
      json_string(r.fitted_yaml));
}

std::string diagnosis_json(const Diagnosis& d) {
  std::string j = "{\n";
  auto out = std::back_inserter(j);
  fmt::format_to(out, "  \"scenario\": {},\n  \"interrupted\": {},\n", json_string(d.scenario),
                 d.interrupted ? "true" : "false");
  fmt::format_to(
      out,
      "  \"verdict\": {{\"effect\": {}, \"where\": {}, \"second\": {}, \"second_effect\": "
      "{}}},\n",
      json_string(d.effect), json_strings(d.verdict_where),
      d.second_candidate >= 0 ? json_string(candidate_name(d, d.second_candidate)) : "null",
      d.second_effect.empty() ? "null" : json_string(d.second_effect));
  fmt::format_to(out, "  \"noise\": {{\"sigma\": {}, \"third_differences\": {}, \"rms\": {}}},\n",
                 json_number(d.noise.sigma), d.noise.differences, json_number(d.noise.naive));
  fmt::format_to(
      out,
      "  \"nominal\": {{\"evaluations\": {}, \"parameters\": {}, \"train_rms\": {}, "
      "\"errors_note\": {}, \"heldout_rms\": {}, \"start_scale\": {}, \"stiffness_scan\": [",
      d.nominal_evaluations, json_values(d.nominal_parameters), json_number(d.nominal_train.rms),
      json_string(d.nominal_errors_note), json_number(heldout_rms(d.nominal_heldout, false)),
      json_number(d.stiffness_scale));
  for (std::size_t k = 0; k < d.stiffness_scan.size(); ++k)
    fmt::format_to(out, "{}{{\"scale\": {}, \"rms\": {}}}", k ? ", " : "",
                   json_number(d.stiffness_scan[k].scale),
                   d.stiffness_scan[k].ok ? json_number(d.stiffness_scan[k].rms) : "null");
  j += "]},\n";
  // Where.
  j += "  \"where\": {\n    \"markers\": [";
  for (std::size_t k = 0; k < d.where.markers.size(); ++k) {
    const auto& m = d.where.markers[k];
    fmt::format_to(
        out,
        "{}\n      {{\"name\": {}, \"region\": {}, \"along\": {}, \"rms\": [{}, {}, {}], "
        "\"rms_total\": {}, \"excess\": {}, \"gain\": {}, \"delay\": {}, "
        "\"main_axis\": \"{}\"}}",
        k ? "," : "", json_string(m.name), json_string(m.region), json_number(m.along),
        json_number(m.rms[0]), json_number(m.rms[1]), json_number(m.rms[2]),
        json_number(m.rms_total), json_number(m.excess), json_number(m.gain), json_number(m.delay),
        "xyz"[m.main_axis]);
  }
  j += "],\n    \"windows\": [";
  for (std::size_t k = 0; k < d.where.windows.size(); ++k)
    fmt::format_to(out, "{}{{\"t0\": {}, \"t1\": {}, \"rms\": {}}}", k ? ", " : "",
                   json_number(d.where.windows[k].t0), json_number(d.where.windows[k].t1),
                   json_number(d.where.windows[k].rms));
  j += "],\n    \"bands\": [";
  for (std::size_t k = 0; k < d.where.bands.size(); ++k)
    fmt::format_to(
        out, "{}{{\"f0\": {}, \"f1\": {}, \"residual_fraction\": {}, \"signal_fraction\": {}}}",
        k ? ", " : "", json_number(d.where.bands[k].f0), json_number(d.where.bands[k].f1),
        json_number(d.where.bands[k].residual_fraction),
        json_number(d.where.bands[k].signal_fraction));
  j += "],\n    \"regions\": [";
  for (std::size_t k = 0; k < d.where.regions.size(); ++k)
    fmt::format_to(out, "{}{{\"name\": {}, \"rms\": {}, \"excess\": {}, \"markers\": {}}}",
                   k ? ", " : "", json_string(d.where.regions[k].name),
                   json_number(d.where.regions[k].rms), json_number(d.where.regions[k].excess),
                   json_strings(d.where.regions[k].markers));
  j += "],\n    \"missing_force\": " +
       missing_force_json(d.missing_force, d.settings.missing_force.enabled);
  j += "\n  },\n";
  // Screening.
  fmt::format_to(out, "  \"screening\": {{\"alpha\": {}, \"ranking\": [",
                 json_number(d.ranking.alpha));
  for (std::size_t k = 0; k < d.ranking.order.size(); ++k) {
    const auto& r = d.ranking.order[k];
    fmt::format_to(
        out,
        "{}\n    {{\"candidate\": {}, \"dof\": {}, \"statistic\": {}, \"p_value\": {}, "
        "\"threshold\": {}, \"predicted_rms\": {}, \"conditional_statistic\": {}, "
        "\"significant\": {}{}{}{}}}",
        k ? "," : "", json_string(candidate_name(d, r.candidate)), r.marginal.dof,
        json_number(r.marginal.statistic), json_number(r.marginal.p_value),
        json_number(r.threshold), json_number(r.marginal.predicted_rms),
        json_number(r.conditional.statistic), r.significant ? "true" : "false",
        heldout_prediction(d, r.candidate).empty()
            ? ""
            : ", \"predicted_heldout_drop\": " + json_number(d.predicted_heldout_drop[r.candidate]),
        r.marginal.error.empty() ? "" : ", \"error\": " + json_string(r.marginal.error),
        d.candidates[r.candidate].screened ? "" : ", \"model_check\": true");
  }
  fmt::format_to(
      out, "],\n    \"refit_order\": {},",
      json_string(d.refit_order_from_heldout ? "predicted held-out drop" : "training statistic"));
  j += "\n    \"confounded\": [";
  for (std::size_t k = 0; k < d.ranking.confounded.size(); ++k) {
    const auto& c = d.ranking.confounded[k];
    fmt::format_to(out, "{}{{\"a\": {}, \"b\": {}, \"correlation\": {}}}", k ? ", " : "",
                   json_string(candidate_name(d, c.a)), json_string(candidate_name(d, c.b)),
                   json_number(c.correlation));
  }
  j += "]},\n  \"second_screening\": [";
  for (std::size_t k = 0; k < d.second_ranking.order.size(); ++k) {
    const auto& r = d.second_ranking.order[k];
    fmt::format_to(out,
                   "{}{{\"candidate\": {}, \"statistic\": {}, \"threshold\": {}, "
                   "\"significant\": {}}}",
                   k ? ", " : "", json_string(candidate_name(d, r.candidate)),
                   json_number(r.marginal.statistic), json_number(r.threshold),
                   r.significant ? "true" : "false");
  }
  j += "],\n  \"refits\": [";
  for (std::size_t k = 0; k < d.refits.size(); ++k)
    j += (k ? ",\n    " : "\n    ") + refit_json(d, d.refits[k]);
  j += "],\n  \"second_refit\": ";
  j += d.second_refit.candidate >= 0 ? refit_json(d, d.second_refit) : "null";
  j += ",\n  \"learned_correction\": ";
  if (d.learned < 0) {
    j += "null";
  } else {
    fmt::format_to(out, "{{\"refit\": {}, \"summary\": {}, \"signature\": [", d.learned,
                   json_string(d.signature.summary));
    for (std::size_t k = 0; k < d.signature.points.size(); ++k) {
      const SignaturePoint& p = d.signature.points[k];
      fmt::format_to(out, "{}{{\"kind\": {}, \"at\": {}, \"value\": {}, \"relative\": {}}}",
                     k ? ", " : "", json_string(p.kind), json_number(p.at), json_number(p.value),
                     json_number(p.relative));
    }
    j += "]}";
  }
  j += ",\n  \"remaining_force\": " +
       missing_force_json(d.remaining_force, d.settings.missing_force.enabled && d.accepted >= 0);
  fmt::format_to(out,
                 ",\n  \"seconds\": {{\"nominal_fit\": {}, \"missing_force\": {}, "
                 "\"screening\": {}, \"refits\": {}, \"heldout\": {}, \"second_screening\": "
                 "{}, \"learned_correction\": {}}},\n  \"fitted\": {}\n}}\n",
                 json_number(d.seconds.nominal_fit), json_number(d.seconds.missing_force),
                 json_number(d.seconds.screening), json_number(d.seconds.refits),
                 json_number(d.seconds.heldout), json_number(d.seconds.second_screening),
                 json_number(d.seconds.learned_correction), json_string(d.fitted_yaml));
  return j;
}

/// Squared distance |simulated − observed|² per (marker, frame) of experiment 0.
using Distances = std::map<std::pair<int, double>, double>;
Distances marker_distances(const Eigen::VectorXd& residual,
                           const std::vector<ResidualSample>& samples) {
  Distances sq;
  for (std::size_t k = 0; k < samples.size() && k < static_cast<std::size_t>(residual.size());
       ++k) {
    const auto& s = samples[k];
    if (s.experiment != 0) continue;
    const double r = residual[static_cast<long>(k)] / s.sqrt_weight;
    sq[{s.marker, s.t}] += r * r;
  }
  return sq;
}

/// The distance noise alone gives (σ̂√3: three coordinates), over [t0, t1].
svg::Series noise_line(const Diagnosis& d, double t0, double t1) {
  svg::Series noise;
  noise.name = "noise σ√3";
  noise.colour = "#000000";
  noise.dashed = true;
  noise.x = {t0, t1};
  noise.y = {1e3 * d.noise.sigma * std::sqrt(3.0), 1e3 * d.noise.sigma * std::sqrt(3.0)};
  return noise;
}

/// One marker's distance over time, in mm.
svg::Series distance_series(const Distances& sq, int marker) {
  svg::Series s;
  for (const auto& [key, v] : sq)
    if (key.first == marker) {
      s.x.push_back(key.second);
      s.y.push_back(1e3 * std::sqrt(v));
    }
  return s;
}

/// The held-out motion's worst markers (by the nominal's misfit), their distance
/// over time before and after the accepted effect; empty without one.
std::string heldout_plot(const Diagnosis& d) {
  if (d.accepted < 0) return {};
  const RefitResult& a = d.refits[d.accepted];
  if (a.heldout.empty() || !a.heldout[0].after.ok ||
      a.heldout[0].after.samples != a.heldout[0].before.samples)
    return {};
  const HeldOutFigures& h = a.heldout[0];
  const Distances before = marker_distances(h.before.residual, h.before.entries),
                  after = marker_distances(h.after.residual, h.after.entries);
  std::map<int, double> misfit;
  for (const auto& [key, v] : before) misfit[key.first] += v;
  std::vector<std::pair<double, int>> worst;
  for (const auto& [marker, v] : misfit) worst.push_back({-v, marker});
  std::sort(worst.begin(), worst.end());
  svg::Figure fig;
  fig.title = fmt::format("Held-out motion {}: the worst markers without and with {}",
                          fs::path(h.path).filename().string(), d.effect);
  for (std::size_t k = 0; k < worst.size() && k < 3; ++k) {
    const int marker = worst[k].second;
    svg::Plot plot;
    plot.title = marker < static_cast<int>(h.marker_names.size()) ? h.marker_names[marker] : "";
    plot.x_label = "t (s)";
    plot.y_label = "|simulated − observed| (mm)";
    svg::Series b = distance_series(before, marker), x = distance_series(after, marker);
    b.name = "nominal";
    b.colour = "#7f7f7f";
    x.name = "with " + d.effect;
    x.colour = "#d62728";
    plot.series = {b, x};
    if (!b.x.empty()) plot.series.push_back(noise_line(d, b.x.front(), b.x.back()));
    fig.panels.push_back(plot);
  }
  return svg::render(fig);
}

/// Residual distance per marker over time (nominal fit, training motion 0).
std::string residual_plot(const Diagnosis& d) {
  svg::Figure fig;
  fig.title = "Residual of the nominal fit per marker";
  svg::Plot plot;
  plot.x_label = "t (s)";
  plot.y_label = "|simulated − observed| (mm)";
  const std::vector<std::string> colours = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728",
                                            "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"};
  const auto distance = marker_distances(d.nominal_train.residual, d.nominal_samples);
  for (std::size_t i = 0; i < d.marker_names.size(); ++i) {
    svg::Series s = distance_series(distance, static_cast<int>(i));
    s.name = d.marker_names[i];
    s.colour = colours[i % colours.size()];
    plot.series.push_back(s);
  }
  if (!distance.empty())
    plot.series.push_back(
        noise_line(d, distance.begin()->first.second, distance.rbegin()->first.second));
  fig.panels.push_back(plot);
  return svg::render(fig);
}

std::string spectrum_plot(const Diagnosis& d) {
  svg::Plot plot;
  plot.title = "Power per frequency band: residual against the observed motion";
  plot.x_label = "band centre (Hz)";
  plot.y_label = "fraction of the total";
  plot.log_x = true;
  svg::Series res, sig;
  res.name = "residual";
  sig.name = "observed motion";
  sig.colour = "#7f7f7f";
  res.style = sig.style = svg::Style::line_and_markers;
  for (const auto& b : d.where.bands) {
    const double centre = b.f0 > 0 ? std::sqrt(b.f0 * b.f1) : 0.5 * b.f1;
    res.x.push_back(centre);
    sig.x.push_back(centre);
    res.y.push_back(b.residual_fraction);
    sig.y.push_back(b.signal_fraction);
  }
  plot.series = {sig, res};
  return svg::render(plot);
}

std::string ranking_plot(const Diagnosis& d) {
  svg::Plot plot;
  plot.title = "Screening: score statistic over its threshold (above 1: significant)";
  plot.x_label = "rank";
  plot.y_label = "statistic / threshold";
  plot.log_y = true;
  svg::Series s, line;
  s.name = "candidates";
  s.style = svg::Style::markers;
  for (std::size_t k = 0; k < d.ranking.order.size(); ++k) {
    const auto& r = d.ranking.order[k];
    s.x.push_back(static_cast<double>(k + 1));
    s.y.push_back(std::max(1e-3, r.marginal.statistic / r.threshold));
    s.labels.push_back(candidate_name(d, r.candidate));
  }
  line.name = "threshold";
  line.colour = "#d62728";
  line.dashed = true;
  line.x = {1, static_cast<double>(std::max<std::size_t>(1, d.ranking.order.size()))};
  line.y = {1, 1};
  plot.series = {s, line};
  return svg::render(plot, 760, 460);
}

std::string missing_force_plot(const MissingForce& f) {
  svg::Plot plot;
  plot.title = "Missing force: share of the field per part of the body";
  plot.x_label = "0 clamp zone, 1 middle, 2 free end";
  plot.y_label = "share of ∫∫|f|² dV dt";
  svg::Series s;
  s.name = "missing force";
  s.style = svg::Style::line_and_markers;
  for (std::size_t k = 0; k < f.regions.size(); ++k) {
    s.x.push_back(static_cast<double>(k));
    s.y.push_back(f.regions[k].share);
    s.labels.push_back(f.regions[k].name);
  }
  plot.series = {s};
  return svg::render(plot);
}

/// `heldout_figure`: heldout.svg was written.
std::string report(const Diagnosis& d, bool heldout_figure) {
  std::string r;
  auto out = std::back_inserter(r);
  fmt::format_to(out, "# Diagnosis of {}\n\n", d.scenario);
  if (d.interrupted) r += "**Interrupted**: the stages below are those that finished.\n\n";
  if (d.effect == "none")
    r += "**Verdict: no significant effect.** No candidate's refit lowered the misfit by more "
         "than the estimated noise can explain";
  else
    fmt::format_to(
        out, "**Verdict: {}** ({}){}.", d.effect,
        d.verdict_where.empty() ? "the whole body" : d.verdict_where[0],
        d.second_effect.empty() ? "" : ", and a second effect: **" + d.second_effect + "**");
  if (d.effect == "none")
    r += d.settings.validate.empty() ? ".\n\n" : " on the training and the held-out motions.\n\n";
  else
    r += "\n\n";
  if (d.accepted >= 0) {
    const RefitResult& a = d.refits[d.accepted];
    fmt::format_to(out, "Adding it lowers the training RMS from {:.4f} to {:.4f} mm per coordinate",
                   d.nominal_train.rms * 1e3, a.train.rms * 1e3);
    if (!a.heldout.empty())
      fmt::format_to(out, " and the held-out RMS from {:.4f} to {:.4f} mm",
                     heldout_rms(a.heldout, false) * 1e3, heldout_rms(a.heldout, true) * 1e3);
    fmt::format_to(out, "; the noise level is {:.4f} mm. Fitted model: `{}`.\n\n",
                   d.noise.sigma * 1e3, a.fitted_yaml);
    if (d.second_candidate >= 0) {
      fmt::format_to(out,
                     "Screened again with it in the model, {} is significant too (LM {:.1f} "
                     "against {:.1f})",
                     candidate_name(d, d.second_candidate),
                     d.second_ranking.order[0].marginal.statistic,
                     d.second_ranking.order[0].threshold);
      const RefitResult& s = d.second_refit;
      if (s.candidate < 0)
        r += "; it was not refitted.\n\n";
      else if (!s.ok)
        fmt::format_to(out, "; its refit failed: {}.\n\n", s.error);
      else
        fmt::format_to(
            out,
            ". Refitted with both, the training RMS goes from {:.4f} to {:.4f} mm (likelihood "
            "ratio {:.1f} against {:.1f}){}: **{}**.\n\n",
            a.train.rms * 1e3, s.train.rms * 1e3, s.statistic, s.threshold,
            s.heldout.empty()
                ? std::string()
                : fmt::format(" and the held-out ‖r‖² drops by {:.4g} mm² (needs {:.3g})",
                              s.heldout_drop * 1e6, s.heldout_threshold * 1e6),
            d.second_effect.empty() ? "not a second effect: the tests do not confirm it"
                                    : "a second effect, in `" + s.fitted_yaml + "`");
    } else if (!d.second_ranking.order.empty())
      r += "Screened again with it in the model, no further candidate is significant.\n\n";
    if (const MissingForce& f = d.remaining_force; f.ok)
      fmt::format_to(
          out,
          "The missing force left with it in the model takes the training RMS from "
          "{:.4f} to {:.4f} mm (likelihood ratio {:.1f} against {:.1f}: {}). {} "
          "(`missing-force-after/body-force.pvd`)\n\n{}\n",
          f.rms_before * 1e3, f.rms_after * 1e3, f.statistic, f.threshold,
          f.statistic > f.threshold ? "something is still missing" : "what is left is noise",
          where_of(f), region_table(f));
    else if (!d.remaining_force.error.empty())
      r += "The missing force left with it in the model: " + d.remaining_force.error + ".\n\n";
  }
  fmt::format_to(out,
                 "## Nominal fit\n\n{} evaluations; training RMS {:.4f} mm per coordinate "
                 "(noise {:.4f} mm from {} third differences of the residual; the plain residual "
                 "RMS would say {:.4f} mm).\n\n| parameter | value | standard error |\n"
                 "|---|---:|---:|\n",
                 d.nominal_evaluations, d.nominal_train.rms * 1e3, d.noise.sigma * 1e3,
                 d.noise.differences, d.noise.naive * 1e3);
  for (const auto& v : d.nominal_parameters)
    fmt::format_to(out, "| {} | {:.6g} | {} |\n", v.name, v.value,
                   std::isfinite(v.std_error) ? fmt::format("{:.2g}", v.std_error) : "—");
  r += "\nStandard errors: Gauss–Newton, σ̂² (JᵀJ)⁻¹ with σ̂² = ‖r‖²/(N − n), which an effect "
       "the model lacks inflates" +
       (d.nominal_errors_note.empty() ? std::string(".") : "; " + d.nominal_errors_note + ".") +
       "\n";
  if (!d.stiffness_scan.empty()) {
    fmt::format_to(out,
                   "\nThe fit started at ×{:.3g} of the scenario's moduli, the best of a scan of "
                   "one common scale of them (forward runs at the first stage's tolerances; "
                   "under periodic motion Φ has a basin per resonance):\n\n| scale | rms (mm) "
                   "|\n|---:|---:|\n",
                   d.stiffness_scale);
    for (const auto& p : d.stiffness_scan)
      fmt::format_to(out, "| {:.3g} | {} |\n", p.scale,
                     p.ok ? fmt::format("{:.4f}", p.rms * 1e3) : "failed");
  }
  r += "\n## Where\n\n![residual per marker](residual.svg)\n\n"
       "| marker | region | along | rms x | rms y | rms z | excess over noise | gain | delay (ms) "
       "|\n"
       "|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const auto& m : d.where.markers)
    fmt::format_to(out,
                   "| {} | {} | {:.2f} | {:.3f} | {:.3f} | {:.3f} | {:.3f} | {:.3f} | {:.2f} |\n",
                   m.name, m.region, m.along, m.rms[0] * 1e3, m.rms[1] * 1e3, m.rms[2] * 1e3,
                   m.excess * 1e3, m.gain, m.delay * 1e3);
  r += "\n(mm; `along` is 0 at the clamp and 1 at the free end; gain and delay of the simulated "
       "track against the observed one on the marker's main axis.)\n\n"
       "| region | rms (mm) | excess (mm) | markers |\n|---|---:|---:|---|\n";
  for (const auto& g : d.where.regions) {
    std::string names;
    for (const auto& n : g.markers) names += (names.empty() ? "" : ", ") + n;
    fmt::format_to(out, "| {} | {:.3f} | {:.3f} | {} |\n", g.name, g.rms * 1e3, g.excess * 1e3,
                   names);
  }
  r += "\n| window (s) | rms (mm) |\n|---|---:|\n";
  for (const auto& w : d.where.windows)
    fmt::format_to(out, "| {:.2f}–{:.2f} | {:.3f} |\n", w.t0, w.t1, w.rms * 1e3);
  r += "\n![spectra](spectrum.svg)\n";
  if (const MissingForce& f = d.missing_force; f.ok) {
    fmt::format_to(
        out,
        "\n### Missing force\n\nThe gentlest body force (per unit mass: {} hats in "
        "time × {} segments along the body × 3 axes, a prior of size g on each, "
        "fitted in {} evaluations with the nominal parameters held) that makes the "
        "nominal model follow the capture takes the training RMS from {:.4f} to "
        "{:.4f} mm per coordinate (likelihood ratio {:.1f}; fitting noise alone "
        "stays below {:.1f} at α for its {} values{}). {} ParaView: "
        "`missing-force/body-force.pvd` (force density per element and knot; "
        "`body-force.csv` the same as a table).\n\n"
        "![missing force per region](missing-force.svg)\n\n",
        f.knots, f.segments, f.evaluations, f.rms_before * 1e3, f.rms_after * 1e3, f.statistic,
        f.threshold, f.dof,
        f.statistic > f.threshold ? "" : ": this field is noise, its place means nothing",
        where_of(f));
    r += region_table(f);
  } else if (d.settings.missing_force.enabled && !d.missing_force.error.empty()) {
    r += "\n### Missing force\n\nNot found: " + d.missing_force.error + "\n";
  }
  r += "\n## Which: screening at the nominal fit\n\n"
       "![ranking](ranking.svg)\n\n"
       "| rank | candidate | dof | score statistic | threshold | predicted rms (mm) | given those "
       "above | significant | predicted held-out ‖h‖² drop (mm²) |\n"
       "|---:|---|---:|---:|---:|---:|---:|---|---:|\n";
  for (std::size_t k = 0; k < d.ranking.order.size(); ++k) {
    const auto& x = d.ranking.order[k];
    fmt::format_to(out, "| {} | {} | {} | {:.1f} | {:.1f} | {:.4f} | {:.1f} | {} | {} |\n", k + 1,
                   candidate_name(d, x.candidate), x.marginal.dof, x.marginal.statistic,
                   x.threshold, x.marginal.predicted_rms * 1e3, x.conditional.statistic,
                   x.significant ? "yes" : "", heldout_prediction(d, x.candidate));
  }
  for (const auto& x : d.ranking.order)
    if (!d.candidates[x.candidate].screened && x.marginal.error.empty())
      fmt::format_to(out,
                     "\n{} has no parameters of its own to score: its row is one run of its "
                     "model at the nominal fit (the statistic: how far the tracks moved, "
                     "‖Δr‖²/σ̂²; the rms: that run's). {}\n",
                     candidate_name(d, x.candidate),
                     x.significant ? "They moved beyond the noise: it is refitted after the "
                                     "top candidates unless one of them, or the nominal fit, "
                                     "leaves only noise."
                                   : "They did not move beyond the noise: it cannot matter.");
  if (d.refit_order_from_heldout)
    r += "\nMore candidates cleared their threshold than are refitted: the refits were chosen "
         "by the held-out drop each one's screening step predicts (a probed candidate: by one "
         "held-out run at its probe).\n";
  fmt::format_to(out,
                 "\nThreshold: the χ²(dof) quantile at α = {:g} over {} candidates (Bonferroni); "
                 "noise from the residual's third differences.\n",
                 d.ranking.alpha, d.ranking.order.size());
  for (const auto& c : d.ranking.confounded)
    fmt::format_to(out,
                   "\n- **Confounded**: {} and {} (canonical correlation {:.3f}): these data "
                   "cannot tell them apart; a motion that excites them differently (another "
                   "frequency, amplitude or direction) would.\n",
                   candidate_name(d, c.a), candidate_name(d, c.b), c.correlation);
  r += "\n## How far: refits\n\n"
       "| candidate | train rms (mm) | LR statistic | threshold | held-out rms (mm) | held-out "
       "drop / threshold | where | parameters |\n|---|---:|---:|---:|---:|---:|---|---|\n";
  // A refit's row; a second effect's is measured from the first's refit (its held-out
  // `before` already is).
  const auto refit_row = [&](const RefitResult& x) {
    const bool second = x.on_top_of >= 0 && d.accepted >= 0;
    const std::string name =
        second ? candidate_name(d, x.on_top_of) + " + " + candidate_name(d, x.candidate)
               : candidate_name(d, x.candidate);
    std::string params;
    for (const auto& v : x.parameters)
      params += fmt::format(
          "{}{} = {:.4g}{}", params.empty() ? "" : ", ", v.name, v.value,
          std::isfinite(v.std_error) ? fmt::format(" ± {:.2g}", v.std_error) : std::string());
    if (!x.errors_note.empty()) params += " (" + x.errors_note + ")";
    if (x.at_nominal) params = "refit ended above its start model; shown there: " + params;
    if (!x.ok) {
      fmt::format_to(out, "| {} | failed: {} | | | | | | |\n", name, x.error);
      return;
    }
    fmt::format_to(out, "| {} | {:.4f} → {:.4f} | {:.1f} | {:.1f} | {} | {} | {} | {} |\n", name,
                   (second ? d.refits[d.accepted].train.rms : d.nominal_train.rms) * 1e3,
                   x.train.rms * 1e3, x.statistic, x.threshold,
                   x.heldout.empty()
                       ? std::string("—")
                       : fmt::format("{:.4f} → {:.4f}", heldout_rms(x.heldout, false) * 1e3,
                                     heldout_rms(x.heldout, true) * 1e3),
                   x.heldout.empty() || !(x.heldout_threshold > 0)
                       ? std::string("—")
                       : fmt::format("{:.2f}", x.heldout_drop / x.heldout_threshold),
                   x.where, params);
  };
  for (const auto& x : d.refits) refit_row(x);
  if (d.second_refit.candidate >= 0) refit_row(d.second_refit);
  if (d.learned >= 0) {
    const RefitResult& x = d.refits[d.learned];
    r += "\n### Learned correction (unnamed)\n\nNo named candidate passed, and the nominal "
         "model leaves more than noise: a correction of the stress (a principal-stretch spline, "
         "zero at rest, and a viscosity growing with the largest stretch) was fitted with the "
         "nominal parameters free.";
    if (x.ok)
      fmt::format_to(out,
                     " It takes the training RMS from {:.4f} to {:.4f} mm{}. Signature: {}.\n\n"
                     "| correction | at | value | relative |\n|---|---:|---:|---:|\n",
                     d.nominal_train.rms * 1e3, x.train.rms * 1e3,
                     d.accepted == d.learned ? " and passes the tests below"
                                             : ", not enough to pass the tests below",
                     d.signature.summary);
    else
      r += " It failed: " + x.error + "\n";
    for (const SignaturePoint& p : d.signature.points)
      fmt::format_to(out, "| {} | {:.3g} | {:.4g} {} | {:+.1f} % |\n",
                     p.kind == "stretch"  ? "f′(s), principal stretch"
                     : p.kind == "volume" ? "h′(J), volume ratio"
                                          : "extra viscosity at largest stretch",
                     p.at, p.value, p.kind == "damping" ? "Pa s" : "Pa", 100 * p.relative);
    r += "\nRelative: an elastic value over M·|s − 1| (M the nominal's largest modulus), the "
         "viscosity over the nominal's. The nominal parameters were refitted with it, and the "
         "correction and their change together are the change of the law:";
    for (std::size_t k = 0; k < x.nominal_parameters.size() && k < d.nominal_parameters.size(); ++k)
      fmt::format_to(out, "{} {} {:.4g} → {:.4g}", k ? "," : "", x.nominal_parameters[k].name,
                     d.nominal_parameters[k].value, x.nominal_parameters[k].value);
    r += ".\n";
  }
  if (heldout_figure)
    r += "\n![held-out motion: the worst markers without and with the effect](heldout.svg)\n";
  r += "\nAn effect is named when its refit's likelihood-ratio statistic (the drop of ‖r‖² "
       "over σ̂²) clears the χ² threshold and, with held-out motions, their ‖r‖² drops by "
       "more than 2 z σ̂ ‖Δh‖ (what fitting noise alone could give, z at the same α).\n";
  fmt::format_to(out,
                 "\nStage times: nominal fit {:.0f} s, missing force {:.0f} s, screening {:.0f} s, "
                 "refits {:.0f} s (held-out checks {:.0f} s), second screening {:.0f} s, "
                 "learned correction {:.0f} s.\n",
                 d.seconds.nominal_fit, d.seconds.missing_force, d.seconds.screening,
                 d.seconds.refits, d.seconds.heldout, d.seconds.second_screening,
                 d.seconds.learned_correction);
  return r;
}

}  // namespace

std::string write_diagnosis_outputs(const Diagnosis& d) {
  const fs::path dir(d.outdir);
  fs::create_directories(dir);
  write_file_atomic((dir / "diagnosis.json").string(), diagnosis_json(d));
  if (!d.nominal_samples.empty()) {
    write_file_atomic((dir / "residual.svg").string(), residual_plot(d));
    write_file_atomic((dir / "spectrum.svg").string(), spectrum_plot(d));
    write_file_atomic((dir / "ranking.svg").string(), ranking_plot(d));
  }
  if (d.missing_force.ok)
    write_file_atomic((dir / "missing-force.svg").string(), missing_force_plot(d.missing_force));
  const std::string heldout = heldout_plot(d);
  if (!heldout.empty()) write_file_atomic((dir / "heldout.svg").string(), heldout);
  std::string csv = "marker,region,along,rms_x,rms_y,rms_z,rms,excess,gain,delay\n";
  for (const auto& m : d.where.markers)
    csv += fmt::format("{},{},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g}\n", m.name,
                       m.region, m.along, m.rms[0], m.rms[1], m.rms[2], m.rms_total, m.excess,
                       m.gain, m.delay);
  write_file_atomic((dir / "where-markers.csv").string(), csv);
  // The accepted model's files, next to the report (fitted.yaml names its field file
  // relative to itself).
  if (!d.fitted_yaml.empty() && fs::exists(d.fitted_yaml) &&
      fs::absolute(d.fitted_yaml) != fs::absolute(dir / "fitted.yaml")) {
    for (const char* name : {"fitted-fields.csv", "fitted.yaml"}) {
      const fs::path from = fs::path(d.fitted_yaml).parent_path() / name;
      if (!fs::exists(from)) continue;
      std::ifstream in(from);
      const std::string text((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
      write_file_atomic((dir / name).string(), text);
    }
  }
  const std::string path = (dir / "report.md").string();
  write_file_atomic(path, report(d, !heldout.empty()));
  return path;
}

}  // namespace kelvin
