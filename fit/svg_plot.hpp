#pragma once
/// \file
/// Minimal SVG line plots (axes, ticks, labels, legend) for reports. Self-contained:
/// the output is a standalone SVG document in a std::string that browsers and
/// Markdown viewers display directly.
#include <string>
#include <string_view>
#include <vector>

namespace kelvin::svg {

enum class Style { line, markers, line_and_markers };

/// One curve. A NaN or infinite value (or a non-positive one on a log axis) breaks
/// the line there, so occluded samples show as gaps rather than as straight joins.
struct Series {
  std::string name;  // legend entry; empty: not listed in the legend
  std::vector<double> x, y;
  std::string colour = "#1f77b4";
  bool dashed = false;
  Style style = Style::line;
  /// Optional text beside each point (e.g. γ on an L-curve); empty entries are skipped.
  std::vector<std::string> labels;
};

struct Plot {
  std::string title, x_label, y_label;
  bool log_x = false, log_y = false;
  std::vector<Series> series;
  /// Vertical lines at these x (e.g. failed evaluations), one legend entry for all.
  std::vector<double> x_marks;
  std::string x_marks_name;
  std::string x_marks_colour = "#d62728";
};

/// Panels stacked vertically under a common title (e.g. x, y, z of one marker).
struct Figure {
  std::string title;
  std::vector<Plot> panels;
  int width = 760, panel_height = 300;
};

/// A standalone SVG document of one plot.
std::string render(const Plot& plot, int width = 760, int height = 420);
/// A standalone SVG document of stacked panels.
std::string render(const Figure& figure);

/// "Nice" tick values (steps of 1, 2 or 5 × 10^k) whose first is <= lo and last
/// >= hi, about `target` intervals. A degenerate range is widened around its value.
std::vector<double> linear_ticks(double lo, double hi, int target = 6);
/// Decades 10^k covering [lo, hi] (both > 0); every second or further decade when
/// the range spans many, so that labels do not collide.
std::vector<double> log_ticks(double lo, double hi);
/// Short tick text: "0.25", "1e-5", "2e6".
std::string tick_label(double value);
/// Text safe inside XML elements and attributes.
std::string xml_escape(std::string_view text);

}  // namespace kelvin::svg
