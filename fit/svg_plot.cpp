#include "fit/svg_plot.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>

namespace kelvin::svg {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// Pixel rectangle of a panel, or of the plotting area inside it.
struct Box {
  double left, top, right, bottom;
  double width() const { return right - left; }
};

/// One axis: data range (the outer ticks), the pixels it maps to, and tick values.
struct Axis {
  bool log = false;
  double lo = 0, hi = 1;  // data units at p0 and p1
  double p0 = 0, p1 = 1;  // pixels
  std::vector<double> ticks;

  bool usable(double v) const { return std::isfinite(v) && (!log || v > 0); }
  double scaled(double v) const { return log ? std::log10(v) : v; }
  double pixel(double v) const {
    return p0 + (scaled(v) - scaled(lo)) / (scaled(hi) - scaled(lo)) * (p1 - p0);
  }
};

struct Point {
  double x, y;    // pixels
  std::size_t i;  // index into the series (for per-point labels)
};

struct LegendEntry {
  std::string name, colour;
  bool dashed;
  Style style;
};

template <typename... Args>
void emit(std::string& out, fmt::format_string<Args...> format, Args&&... args) {
  fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
}

double pow10(int e) {
  return std::pow(10.0, e);
}

/// Data values on one axis over all series (and the x marks), for its range.
std::vector<double> axis_values(const Plot& plot, bool x_axis) {
  std::vector<double> values;
  for (const auto& s : plot.series) {
    const auto& v = x_axis ? s.x : s.y;
    values.insert(values.end(), v.begin(), v.end());
  }
  if (x_axis) values.insert(values.end(), plot.x_marks.begin(), plot.x_marks.end());
  return values;
}

Axis make_axis(const std::vector<double>& values, bool log, double p0, double p1) {
  Axis axis;
  axis.log = log;
  axis.p0 = p0;
  axis.p1 = p1;
  double lo = kInf, hi = -kInf;
  for (double v : values)
    if (axis.usable(v)) {
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  if (lo > hi) {  // nothing to show: an empty but well-formed axis
    lo = log ? 1 : 0;
    hi = log ? 10 : 1;
  }
  axis.ticks = log ? log_ticks(lo, hi) : linear_ticks(lo, hi);
  axis.lo = axis.ticks.front();
  axis.hi = axis.ticks.back();
  return axis;
}

/// Unlabelled 2…9 × 10^k lines, so that a log axis spanning few decades stays readable.
std::vector<double> minor_ticks(const Axis& axis) {
  std::vector<double> out;
  if (!axis.log || axis.ticks.size() > 4 || axis.ticks.size() < 2 ||
      axis.ticks[1] / axis.ticks[0] > 10.5)
    return out;
  for (std::size_t k = 0; k + 1 < axis.ticks.size(); ++k)
    for (int m = 2; m <= 9; ++m) out.push_back(m * axis.ticks[k]);
  return out;
}

/// Runs of consecutive usable points; an unusable value ends the run.
std::vector<std::vector<Point>> segments(const Series& s, const Axis& xa, const Axis& ya) {
  std::vector<std::vector<Point>> out(1);
  const std::size_t n = std::min(s.x.size(), s.y.size());
  for (std::size_t i = 0; i < n; ++i) {
    if (xa.usable(s.x[i]) && ya.usable(s.y[i])) {
      out.back().push_back({xa.pixel(s.x[i]), ya.pixel(s.y[i]), i});
    } else if (!out.back().empty()) {
      out.emplace_back();
    }
  }
  if (out.back().empty()) out.pop_back();
  return out;
}

std::string dash_attribute(bool dashed) {
  return dashed ? " stroke-dasharray=\"6 4\"" : "";
}

void draw_line(std::string& out, const Series& s, const std::vector<std::vector<Point>>& segs) {
  if (segs.empty()) return;
  std::string d;
  for (const auto& seg : segs) {
    emit(d, "M{:.1f},{:.1f}", seg[0].x, seg[0].y);
    for (std::size_t j = 1; j < seg.size(); ++j) emit(d, " L{:.1f},{:.1f}", seg[j].x, seg[j].y);
    if (seg.size() == 1) d += " h0";  // a lone sample between gaps: a round-capped dot
    d += ' ';
  }
  d.pop_back();
  emit(out,
       "<path d=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.6\" "
       "stroke-linejoin=\"round\" stroke-linecap=\"round\"{}/>\n",
       d, xml_escape(s.colour), dash_attribute(s.dashed));
}

void draw_markers(std::string& out, const Series& s, const std::vector<std::vector<Point>>& segs) {
  for (const auto& seg : segs)
    for (const auto& p : seg)
      emit(out, "<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"2.5\" fill=\"{}\"/>\n", p.x, p.y,
           xml_escape(s.colour));
}

void draw_point_labels(std::string& out, const Series& s,
                       const std::vector<std::vector<Point>>& segs) {
  for (const auto& seg : segs)
    for (const auto& p : seg)
      if (p.i < s.labels.size() && !s.labels[p.i].empty())
        emit(out, "<text x=\"{:.1f}\" y=\"{:.1f}\" font-size=\"10\" fill=\"#333\">{}</text>\n",
             p.x + 5, p.y - 5, xml_escape(s.labels[p.i]));
}

void draw_series(std::string& out, const Series& s, const Axis& xa, const Axis& ya) {
  const auto segs = segments(s, xa, ya);
  if (s.style != Style::markers) draw_line(out, s, segs);
  if (s.style != Style::line) draw_markers(out, s, segs);
  draw_point_labels(out, s, segs);
}

/// One grid line at v with an optional label: vertical and labelled below on the x axis,
/// horizontal and labelled on the left on the y axis.
void draw_tick(std::string& out, const Axis& axis, bool x_axis, double v, const Box& area,
               const char* stroke, bool label) {
  const double p = axis.pixel(v);
  if (x_axis)
    emit(out,
         "<line x1=\"{0:.1f}\" y1=\"{1:.1f}\" x2=\"{0:.1f}\" y2=\"{2:.1f}\" stroke=\"{3}\"/>\n", p,
         area.top, area.bottom, stroke);
  else
    emit(out,
         "<line x1=\"{1:.1f}\" y1=\"{0:.1f}\" x2=\"{2:.1f}\" y2=\"{0:.1f}\" stroke=\"{3}\"/>\n", p,
         area.left, area.right, stroke);
  if (!label) return;
  if (x_axis)
    emit(out, "<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n", p,
         area.bottom + 15, xml_escape(tick_label(v)));
  else
    emit(out, "<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"end\">{}</text>\n", area.left - 6,
         p + 4, xml_escape(tick_label(v)));
}

void draw_axis_ticks(std::string& out, const Axis& axis, bool x_axis, const Box& area) {
  // On a log axis of one or two decades the decade labels alone are too sparse to read
  // values off, so 2× and 5× get labels too.
  const bool label_minor = axis.ticks.size() <= 3;
  for (double v : minor_ticks(axis)) {
    const double m = v / axis.ticks[0];
    const double mantissa = m / std::pow(10.0, std::floor(std::log10(m) + 1e-9));
    const bool label =
        label_minor && (std::abs(mantissa - 2) < 1e-6 || std::abs(mantissa - 5) < 1e-6);
    draw_tick(out, axis, x_axis, v, area, label ? "#e8e8e8" : "#f2f2f2", label);
  }
  for (double v : axis.ticks) draw_tick(out, axis, x_axis, v, area, "#ddd", true);
}

void draw_grid(std::string& out, const Axis& xa, const Axis& ya, const Box& area) {
  draw_axis_ticks(out, xa, true, area);
  draw_axis_ticks(out, ya, false, area);
  emit(out,
       "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" fill=\"none\" "
       "stroke=\"#444\"/>\n",
       area.left, area.top, area.width(), area.bottom - area.top);
}

void draw_titles(std::string& out, const Plot& plot, const Box& area, const Box& panel) {
  const double mid = (area.left + area.right) / 2;
  if (!plot.title.empty())
    emit(out,
         "<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\" font-size=\"13\" "
         "font-weight=\"bold\">{}</text>\n",
         mid, panel.top + 19, xml_escape(plot.title));
  if (!plot.x_label.empty())
    emit(out, "<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n", mid,
         area.bottom + 33, xml_escape(plot.x_label));
  if (!plot.y_label.empty()) {
    const double x = panel.left + 16, y = (area.top + area.bottom) / 2;
    emit(out,
         "<text x=\"{0:.1f}\" y=\"{1:.1f}\" text-anchor=\"middle\" "
         "transform=\"rotate(-90 {0:.1f} {1:.1f})\">{2}</text>\n",
         x, y, xml_escape(plot.y_label));
  }
}

void draw_x_marks(std::string& out, const Plot& plot, const Axis& xa, const Box& area) {
  for (double v : plot.x_marks)
    if (xa.usable(v))
      emit(out,
           "<line x1=\"{0:.1f}\" y1=\"{1:.1f}\" x2=\"{0:.1f}\" y2=\"{2:.1f}\" stroke=\"{3}\" "
           "stroke-opacity=\"0.6\"/>\n",
           xa.pixel(v), area.top, area.bottom, xml_escape(plot.x_marks_colour));
}

std::vector<LegendEntry> legend_entries(const Plot& plot) {
  std::vector<LegendEntry> out;
  for (const auto& s : plot.series)
    if (!s.name.empty()) out.push_back({s.name, s.colour, s.dashed, s.style});
  if (!plot.x_marks.empty() && !plot.x_marks_name.empty())
    out.push_back({plot.x_marks_name, plot.x_marks_colour, false, Style::line});
  return out;
}

/// Code points, not bytes: legend names may hold Greek letters and arrows.
std::size_t utf8_length(std::string_view text) {
  return std::count_if(text.begin(), text.end(),
                       [](char c) { return (static_cast<unsigned char>(c) & 0xC0) != 0x80; });
}

/// Width reserved right of the plotting area; text width estimated at 6.5 px per character.
double legend_width(const std::vector<LegendEntry>& entries) {
  if (entries.empty()) return 0;
  std::size_t chars = 0;
  for (const auto& e : entries) chars = std::max(chars, utf8_length(e.name));
  return std::min(40 + 6.5 * static_cast<double>(chars), 260.0);
}

void draw_legend(std::string& out, const std::vector<LegendEntry>& entries, double x, double y) {
  for (const auto& e : entries) {
    const std::string colour = xml_escape(e.colour);
    if (e.style != Style::markers)
      emit(out,
           "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"{}\" "
           "stroke-width=\"1.6\"{}/>\n",
           x, y, x + 24, y, colour, dash_attribute(e.dashed));
    if (e.style != Style::line)
      emit(out, "<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"2.5\" fill=\"{}\"/>\n", x + 12, y, colour);
    emit(out, "<text x=\"{:.1f}\" y=\"{:.1f}\">{}</text>\n", x + 30, y + 4, xml_escape(e.name));
    y += 18;
  }
}

void draw_panel(std::string& out, const Plot& plot, const Box& panel) {
  const auto entries = legend_entries(plot);
  const double legend = legend_width(entries);
  const Box area{panel.left + 72, panel.top + 30, panel.right - legend - 16, panel.bottom - 46};
  const Axis xa = make_axis(axis_values(plot, true), plot.log_x, area.left, area.right);
  const Axis ya = make_axis(axis_values(plot, false), plot.log_y, area.bottom, area.top);
  draw_grid(out, xa, ya, area);
  draw_titles(out, plot, area, panel);
  draw_x_marks(out, plot, xa, area);
  for (const auto& s : plot.series) draw_series(out, s, xa, ya);
  draw_legend(out, entries, area.right + 14, area.top + 8);
}

}  // namespace

std::vector<double> linear_ticks(double lo, double hi, int target) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0, hi = 1;
  if (lo > hi) std::swap(lo, hi);
  if (hi - lo <= 1e-12 * std::max(std::abs(lo), std::abs(hi))) {  // one value: frame it
    const double pad = lo == 0 ? 1 : 0.1 * std::abs(lo);
    lo -= pad;
    hi += pad;
  }
  const double raw = (hi - lo) / std::max(target, 1);
  int e = static_cast<int>(std::floor(std::log10(raw)));
  const double f = raw / pow10(e);
  int mantissa = f <= 1 ? 1 : f <= 2 ? 2 : f <= 5 ? 5 : 10;
  if (mantissa == 10) mantissa = 1, ++e;
  // k·m / 10^−e rather than k·(m·10^e): 3 / 10 is the double nearest 0.3, 3 · 0.1 is not.
  const auto tick = [&](long k) {
    const double km = static_cast<double>(k) * mantissa;
    return e >= 0 ? km * pow10(e) : km / pow10(-e);
  };
  const double step = tick(1);
  const long k0 = static_cast<long>(std::floor(lo / step + 1e-9));
  const long k1 = static_cast<long>(std::ceil(hi / step - 1e-9));
  std::vector<double> out;
  for (long k = k0; k <= k1; ++k) out.push_back(tick(k));
  return out;
}

std::vector<double> log_ticks(double lo, double hi) {
  if (!(lo > 0) || !std::isfinite(lo)) lo = 1;
  if (!(hi > 0) || !std::isfinite(hi)) hi = lo;
  if (lo > hi) std::swap(lo, hi);
  int e0 = static_cast<int>(std::floor(std::log10(lo) + 1e-9));
  int e1 = static_cast<int>(std::ceil(std::log10(hi) - 1e-9));
  if (e1 <= e0) e1 = e0 + 1;
  constexpr int kMaxLabels = 8;
  const int stride = (e1 - e0 + kMaxLabels - 1) / kMaxLabels;
  e0 = static_cast<int>(std::floor(static_cast<double>(e0) / stride)) * stride;  // 1e-4, 1e-2, 1
  std::vector<double> out;
  for (int e = e0;; e += stride) {
    out.push_back(pow10(e));
    if (e >= e1) break;
  }
  return out;
}

std::string tick_label(double value) {
  if (value == 0) return "0";  // also −0
  std::string s = fmt::format("{:.6g}", value);
  const auto e = s.find('e');
  if (e == std::string::npos) return s;
  // "1e-05" → "1e-5", "2e+06" → "2e6"
  const bool negative = s[e + 1] == '-';
  const auto digits = s.find_first_not_of('0', e + 2);
  if (digits == std::string::npos) return s.substr(0, e);  // "e+00": no exponent at all
  return s.substr(0, e + 1) + (negative ? "-" : "") + s.substr(digits);
}

std::string xml_escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        // Control characters other than tab/newline are not allowed in XML 1.0 at all.
        out +=
            static_cast<unsigned char>(c) < 0x20 && c != '\t' && c != '\n' && c != '\r' ? '?' : c;
    }
  }
  return out;
}

std::string render(const Plot& plot, int width, int height) {
  return render(Figure{"", {plot}, width, height});
}

std::string render(const Figure& figure) {
  const double title_height = figure.title.empty() ? 0 : 30;
  const double height =
      title_height + static_cast<double>(figure.panels.size()) * figure.panel_height;
  std::string out;
  emit(out,
       "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" "
       "viewBox=\"0 0 {0} {1}\" font-family=\"sans-serif\" font-size=\"11\">\n"
       "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
       figure.width, height);
  if (!figure.title.empty())
    emit(out,
         "<text x=\"{:.1f}\" y=\"21\" text-anchor=\"middle\" font-size=\"15\" "
         "font-weight=\"bold\">{}</text>\n",
         figure.width / 2.0, xml_escape(figure.title));
  for (std::size_t k = 0; k < figure.panels.size(); ++k) {
    const double top = title_height + static_cast<double>(k) * figure.panel_height;
    draw_panel(out, figure.panels[k], Box{0, top, double(figure.width), top + figure.panel_height});
  }
  out += "</svg>\n";
  return out;
}

}  // namespace kelvin::svg
