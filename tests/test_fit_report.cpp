#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <regex>
#include <sstream>

#include "base/error.hpp"
#include "fit/fit_report.hpp"
#include "fit/fit_state.hpp"
#include "fit/svg_plot.hpp"

namespace fs = std::filesystem;
using kelvin::svg::Plot;
using kelvin::svg::Series;
using kelvin::svg::Style;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Series line(std::string name, std::vector<double> x, std::vector<double> y) {
  Series s;
  s.name = std::move(name);
  s.x = std::move(x);
  s.y = std::move(y);
  return s;
}

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto pos = text.find(what); pos != std::string::npos; pos = text.find(what, pos + 1)) ++n;
  return n;
}

/// The d attributes of every <path> in an SVG.
std::vector<std::string> path_data(const std::string& svg) {
  std::vector<std::string> out;
  const std::regex re("<path d=\"([^\"]*)\"");
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), re); it != std::sregex_iterator();
       ++it)
    out.push_back((*it)[1]);
  return out;
}

/// Cheap structural checks: one root, balanced elements we emit, no raw '&' or '<' in text.
void expect_well_formed(const std::string& svg) {
  EXPECT_EQ(svg.rfind("<svg xmlns=\"http://www.w3.org/2000/svg\"", 0), 0u);
  ASSERT_GE(svg.size(), 7u);
  EXPECT_EQ(svg.substr(svg.find_last_not_of('\n') - 5, 6), "</svg>");
  EXPECT_EQ(count(svg, "<svg"), 1u);
  EXPECT_EQ(count(svg, "<text"), count(svg, "</text>"));
  EXPECT_EQ(count(svg, "<"), count(svg, ">"));
  EXPECT_FALSE(std::regex_search(svg, std::regex("&(?!amp;|lt;|gt;|quot;|apos;)")));
}

/// Ticks step by m·10^k with m in {1, 2, 5}, and first ≤ lo, last ≥ hi.
void expect_nice_cover(double lo, double hi) {
  SCOPED_TRACE(fmt::format("range [{}, {}]", lo, hi));
  const auto ticks = kelvin::svg::linear_ticks(lo, hi);
  ASSERT_GE(ticks.size(), 3u);
  EXPECT_LE(ticks.size(), 14u);
  const double step = ticks[1] - ticks[0];
  const double tol = 1e-9 * step;
  EXPECT_LE(ticks.front(), lo + tol);
  EXPECT_GE(ticks.back(), hi - tol);
  const double mantissa = step / std::pow(10.0, std::floor(std::log10(step) + 1e-9));
  EXPECT_TRUE(std::abs(mantissa - 1) < 1e-9 || std::abs(mantissa - 2) < 1e-9 ||
              std::abs(mantissa - 5) < 1e-9)
      << "step " << step;
  for (std::size_t k = 0; k < ticks.size(); ++k) {
    EXPECT_NEAR(ticks[k] / step, std::round(ticks[k] / step), 1e-9) << ticks[k];
    if (k > 0) {
      EXPECT_NEAR(ticks[k] - ticks[k - 1], step, tol);
    }
  }
}

TEST(SvgTicks, LinearTicksAreNiceAndCoverTheRange) {
  expect_nice_cover(0.13, 0.87);
  expect_nice_cover(-3.2, 47);
  expect_nice_cover(1234, 98765);
  expect_nice_cover(-1e-6, 3e-6);
  expect_nice_cover(0, 1);
  expect_nice_cover(5, 5);  // a single value gets a frame around it
  expect_nice_cover(0, 0);
  EXPECT_EQ(kelvin::svg::linear_ticks(0, 1), (std::vector<double>{0, 0.2, 0.4, 0.6, 0.8, 1}));
}

TEST(SvgTicks, LogTicksAreDecadesCoveringTheRange) {
  const auto ticks = kelvin::svg::log_ticks(0.003, 420);
  EXPECT_EQ(ticks, (std::vector<double>{1e-3, 1e-2, 1e-1, 1, 10, 100, 1000}));
  const auto wide = kelvin::svg::log_ticks(3e-13, 2e11);
  EXPECT_LE(wide.size(), 10u);
  EXPECT_LE(wide.front(), 3e-13);
  EXPECT_GE(wide.back(), 2e11);
  for (std::size_t k = 0; k < wide.size(); ++k) {
    const double e = std::log10(wide[k]);
    EXPECT_NEAR(e, std::round(e), 1e-12);
    if (k > 0) {
      EXPECT_NEAR(e - std::log10(wide[k - 1]), std::log10(wide[1] / wide[0]), 1e-9);
    }
  }
  EXPECT_EQ(kelvin::svg::log_ticks(2, 8), (std::vector<double>{1, 10}));
}

TEST(SvgTicks, LabelsAreShort) {
  EXPECT_EQ(kelvin::svg::tick_label(kelvin::svg::linear_ticks(0, 1)[3]), "0.6");
  EXPECT_EQ(kelvin::svg::tick_label(1e-5), "1e-5");
  EXPECT_EQ(kelvin::svg::tick_label(2e6), "2e6");
  EXPECT_EQ(kelvin::svg::tick_label(-0.0), "0");
  EXPECT_EQ(kelvin::svg::tick_label(250), "250");
}

TEST(SvgPlot, EscapesXmlText) {
  EXPECT_EQ(kelvin::svg::xml_escape("a<b & \"c\" > 'd'"),
            "a&lt;b &amp; &quot;c&quot; &gt; &apos;d&apos;");
  Plot plot;
  plot.title = "E < 5 & ν > 0";
  plot.series = {line("<&series>", {0, 1}, {0, 1})};
  const std::string svg = kelvin::svg::render(plot);
  expect_well_formed(svg);
  EXPECT_NE(svg.find("E &lt; 5 &amp; ν &gt; 0"), std::string::npos);
  EXPECT_NE(svg.find("&lt;&amp;series&gt;"), std::string::npos);
  EXPECT_EQ(svg.find("<&"), std::string::npos);
}

TEST(SvgPlot, NonFiniteSamplesBreakTheLine) {
  const double inf = std::numeric_limits<double>::infinity();
  Plot plot;
  plot.series = {
      line("track", {0, 1, 2, 3, 4, 5, 6, 7, 8, 9}, {1, 2, 3, kNaN, 5, 6, 7, inf, 9, 10})};
  const auto paths = path_data(kelvin::svg::render(plot));
  ASSERT_EQ(paths.size(), 1u);
  EXPECT_EQ(count(paths[0], "M"), 3u);
  EXPECT_EQ(count(paths[0], "L"), 2u + 2u + 1u);

  // Leading, trailing and repeated gaps do not make empty segments; a lone sample
  // between gaps still shows.
  plot.series[0].y = {kNaN, 1, kNaN, kNaN, 4, 5, kNaN, kNaN, kNaN, kNaN};
  const auto gaps = path_data(kelvin::svg::render(plot));
  ASSERT_EQ(gaps.size(), 1u);
  EXPECT_EQ(count(gaps[0], "M"), 2u);
  EXPECT_EQ(count(gaps[0], "h0"), 1u);
}

TEST(SvgPlot, LogAxisDropsNonPositiveValues) {
  Plot plot;
  plot.log_y = true;
  plot.series = {line("objective", {0.1, 0.2, 0.3, 0.4, 0.5},
                      {100, 10, 0, 1, -1})};  // x labels stay apart from y labels
  const std::string svg = kelvin::svg::render(plot);
  expect_well_formed(svg);
  const auto paths = path_data(svg);
  ASSERT_EQ(paths.size(), 1u);
  EXPECT_EQ(count(paths[0], "M"), 2u);
  // Decades from 1 to 100; only two of them, so 2× and 5× are labelled too.
  for (const char* label : {">1<", ">10<", ">100<", ">2<", ">50<"})
    EXPECT_NE(svg.find(label), std::string::npos) << label;
  EXPECT_EQ(svg.find(">30<"), std::string::npos);

  // Over many decades only the decades are labelled.
  plot.series[0].y = {1e-6, 1, 1e3, 1e5, 1e6};
  const std::string wide = kelvin::svg::render(plot);
  EXPECT_NE(wide.find(">1e-6<"), std::string::npos);
  EXPECT_NE(wide.find(">1e6<"), std::string::npos);
  EXPECT_EQ(wide.find(">2<"), std::string::npos);
  EXPECT_EQ(wide.find(">5<"), std::string::npos);
}

TEST(SvgPlot, StylesAndLegend) {
  Plot plot;
  plot.series = {{"dots", {0, 1, 2}, {0, 1, 4}, "#123456", false, Style::markers, {}},
                 {"dashed", {0, 1, 2}, {0, 2, 3}, "#654321", true, Style::line, {"a", "", "c"}}};
  plot.x_marks = {1.5};
  plot.x_marks_name = "failed";
  const std::string svg = kelvin::svg::render(plot);
  expect_well_formed(svg);
  EXPECT_EQ(path_data(svg).size(), 1u);                // only the dashed series is a line
  EXPECT_EQ(count(svg, "fill=\"#123456\""), 3u + 1u);  // three dots and the legend's
  EXPECT_EQ(count(svg, "stroke-dasharray"), 2u);       // the line and its legend sample
  EXPECT_NE(svg.find(">dots</text>"), std::string::npos);
  EXPECT_NE(svg.find(">dashed</text>"), std::string::npos);
  EXPECT_NE(svg.find(">failed</text>"), std::string::npos);
  EXPECT_NE(svg.find(">a</text>"), std::string::npos);
  EXPECT_NE(svg.find(">c</text>"), std::string::npos);
}

TEST(SvgPlot, FigureStacksPanels) {
  kelvin::svg::Figure figure;
  figure.title = "three";
  for (int k = 0; k < 3; ++k) {
    Plot panel;
    panel.title = fmt::format("panel {}", k);
    panel.series = {line("x", {0, 1}, {double(k), k + 1.0})};
    figure.panels.push_back(panel);
  }
  const std::string svg = kelvin::svg::render(figure);
  expect_well_formed(svg);
  EXPECT_EQ(count(svg, "fill=\"none\" stroke=\"#444\""), 3u);  // one frame per panel
  EXPECT_NE(svg.find("height=\"930\""), std::string::npos);
}

// ---------------------------------------------------------------- write_fit_report

class FitReportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("kelvin_test_fit_report_" + std::to_string(::getpid())) /
           info->name();
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_.parent_path()); }

  static std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
  }

  /// Lines of report.md from the heading `## name` up to the next heading.
  static std::vector<std::string> section(const std::string& md, const std::string& name) {
    std::vector<std::string> out;
    std::istringstream in(md.substr(md.find("## " + name + "\n")));
    std::string line;
    std::getline(in, line);
    while (std::getline(in, line) && line.rfind("## ", 0) != 0) out.push_back(line);
    return out;
  }

  static std::vector<std::string> table_rows(const std::vector<std::string>& lines) {
    std::vector<std::string> out;
    for (const auto& l : lines)
      if (l.rfind("| ", 0) == 0) out.push_back(l);
    return out.empty() ? out : std::vector<std::string>(out.begin() + 1, out.end());  // header
  }

  static std::vector<std::string> cells(const std::string& row) {
    std::vector<std::string> out;
    std::istringstream in(row.substr(1));
    std::string c;
    while (std::getline(in, c, '|')) out.push_back(c.substr(1, c.size() - 2));
    return out;
  }

  static kelvin::TrackPlot track(const std::string& marker) {
    kelvin::TrackPlot t;
    t.experiment = "squeeze";
    t.marker = marker;
    const int n = 20;
    t.observed.resize(3, n);
    t.before.resize(3, n);
    t.after.resize(3, n);
    for (int f = 0; f < n; ++f) {
      t.t.push_back(0.01 * f);
      const Eigen::Vector3d x(0.1 + 0.001 * f, 0.2, 0.3 - 0.0005 * f);
      t.observed.col(f) = x;
      t.before.col(f) = 1.2 * x;
      t.after.col(f) = x + Eigen::Vector3d::Constant(1e-5);
    }
    t.observed.col(7).setConstant(kNaN);  // occluded
    t.rms_before = 0.004;
    t.rms_after = 0.0002;
    return t;
  }

  static kelvin::FitReportData data() {
    kelvin::FitReportData d;
    d.title = "cube";
    d.scenario_path = "scenarios/cube.yaml";
    d.algorithm = "lbfgs";
    d.gradient_method = "adjoint";
    d.stop_reason = "stopped: ftol_rel reached";
    d.evaluations = 6;
    d.failures = 1;
    d.seconds = 83;
    d.labels = {"elastic.mu", "elastic.lambda"};
    d.initial = Eigen::Vector2d(1000, 5000);
    d.fitted = Eigen::Vector2d(2500, 7500);
    d.std_error = Eigen::Vector2d(125, 30);
    d.lower = Eigen::Vector2d(10, 0);
    d.upper = Eigen::Vector2d(1e6, std::numeric_limits<double>::infinity());
    d.noise_sigma = 1e-4;
    d.rms_before = 0.003;
    d.rms_after = 0.0005;
    for (int i = 0; i < 35; ++i)
      d.markers.push_back({"squeeze", fmt::format("m{}", i), 0.003, 0.0001 * ((i * 7) % 35)});
    d.markers[3].after = kNaN;  // its simulation failed: listed first
    d.tracks = {track("m1"), track("m2")};
    for (int e = 1; e <= 6; ++e) {
      kelvin::FitRecord r;
      r.evaluation = e;
      r.ok = e != 4;
      r.objective = r.ok ? 1.0 / e : kelvin::kFailedObjective;
      r.misfit = 0.9 / e;
      r.penalty = 0.1 / e;
      d.history.push_back(r);
    }
    for (double g : {1e-3, 1e-2, 1e-1})
      d.lcurve.push_back({g, 1 + 10 * g, 1 / (g * 100), 0.001, 12, {}});
    d.extra_sections = {"## Coarsening\n\nverbatim text\n"};
    d.files = {"fitted.yaml", "history.csv"};
    return d;
  }

  std::vector<std::string> temp_files() const {
    std::vector<std::string> out;
    for (const auto& e : fs::recursive_directory_iterator(dir_))
      if (e.path().filename().string().find(".tmp") != std::string::npos)
        out.push_back(e.path().string());
    return out;
  }

  fs::path dir_;
};

TEST_F(FitReportTest, WritesReportAndPlots) {
  const std::string path = kelvin::write_fit_report(dir_.string(), data());
  EXPECT_EQ(fs::path(path), dir_ / "report.md");
  for (const char* name : {"objective.svg", "track-1.svg", "track-2.svg", "lcurve.svg"}) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(fs::exists(dir_ / name));
    expect_well_formed(slurp(dir_ / name));
  }
  EXPECT_TRUE(temp_files().empty());
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 5);

  const std::string md = slurp(path);
  EXPECT_EQ(md.rfind("# Fit report: cube\n", 0), 0u);
  EXPECT_NE(md.find("**Marker RMS 3 mm → 0.5 mm** (-83.3 %)"), std::string::npos);
  EXPECT_NE(md.find("6 evaluations, 1 failed · 1 min 23 s · lbfgs (adjoint gradients) · "
                    "stopped: ftol_rel reached"),
            std::string::npos);
  EXPECT_NE(md.find("without interruption"), std::string::npos);
  EXPECT_NE(md.find("σ = 0.1 mm"), std::string::npos);
  for (const char* name : {"objective.svg", "track-1.svg", "track-2.svg", "lcurve.svg"})
    EXPECT_NE(md.find(fmt::format("]({})", name)), std::string::npos) << name;
  EXPECT_NE(md.find("## Coarsening\n\nverbatim text\n"), std::string::npos);
  for (const char* name : {"report.md", "objective.svg", "fitted.yaml", "history.csv"})
    EXPECT_NE(md.find(fmt::format("- [{0}]({0})", name)), std::string::npos) << name;

  const auto params = table_rows(section(md, "Parameters"));
  ASSERT_EQ(params.size(), 2u);
  EXPECT_EQ(cells(params[0]),
            (std::vector<std::string>{"elastic.mu", "1000", "2500", "± 125 (5.0 %)", "[10, 1e+06]",
                                      "2.5", ""}));
  EXPECT_EQ(cells(params[1]), (std::vector<std::string>{"elastic.lambda", "5000", "7500",
                                                        "± 30 (0.4 %)", "[0, ∞]", "1.5", ""}));
}

TEST_F(FitReportTest, MarkersWorstFirstAndCapped) {
  const std::string md = slurp(kelvin::write_fit_report(dir_.string(), data()));
  const auto lines = section(md, "Markers");
  const auto rows = table_rows(lines);
  ASSERT_EQ(rows.size(), 30u);
  EXPECT_EQ(cells(rows[0])[1], "m3");  // failed simulation: the worst of all
  EXPECT_EQ(cells(rows[0])[3], "—");
  double previous = std::numeric_limits<double>::infinity();
  for (std::size_t i = 1; i < rows.size(); ++i) {
    const double after = std::stod(cells(rows[i])[3]);
    EXPECT_LE(after, previous) << rows[i];
    previous = after;
  }
  EXPECT_NE(md.find("5 more markers not listed"), std::string::npos);
}

TEST_F(FitReportTest, ManyParametersAreSummarised) {
  kelvin::FitReportData d = data();
  const int n = 500;
  d.labels.clear();
  d.initial.setConstant(n, 1000);
  d.fitted.resize(n);
  d.lower.setConstant(n, 1);
  d.upper.setConstant(n, 1e9);
  d.std_error.resize(0);  // not computed for this many
  for (int j = 0; j < n; ++j) {
    d.labels.push_back(fmt::format("elastic.mu[tet {}]", j));
    d.fitted[j] = 1000 + j;
  }
  const std::string md = slurp(kelvin::write_fit_report(dir_.string(), d));
  const auto lines = section(md, "Parameters");
  const auto rows = table_rows(lines);
  // 40 listed entries, then the summary table's header and its one row for the field.
  ASSERT_EQ(rows.size(), 42u);
  EXPECT_EQ(cells(rows[0]).size(), 6u);  // no std. error column
  EXPECT_NE(md.find("460 further entries"), std::string::npos);
  EXPECT_EQ(cells(rows[41]),
            (std::vector<std::string>{"elastic.mu", "460", "1040", "1270", "1499"}));
  EXPECT_EQ(md.find("tet 40]"), std::string::npos);
}

TEST_F(FitReportTest, ObjectivePlotSkipsFailures) {
  kelvin::write_fit_report(dir_.string(), data());
  const std::string svg = slurp(dir_ / "objective.svg");
  EXPECT_NE(svg.find(">failed evaluation</text>"), std::string::npos);
  EXPECT_NE(svg.find(">misfit Φ at best</text>"), std::string::npos);  // penalty present
  EXPECT_EQ(svg.find("1e30"), std::string::npos);  // the failed objective is no data
  EXPECT_NE(svg.find(">0.1</text>"), std::string::npos);
  EXPECT_NE(svg.find(">1</text>"), std::string::npos);
}

TEST_F(FitReportTest, TrackGapsAtOccludedFrames) {
  kelvin::write_fit_report(dir_.string(), data());
  const std::string svg = slurp(dir_ / "track-1.svg");
  EXPECT_NE(svg.find("x − x₀ (mm)"), std::string::npos);
  EXPECT_NE(svg.find("Marker m1 (squeeze): RMS 4 mm → 0.2 mm"), std::string::npos);
  // Observed dots: 19 per panel (frame 7 occluded), plus one legend dot per panel.
  EXPECT_EQ(count(svg, "fill=\"#333333\""), 3u * (19u + 1u));
  EXPECT_EQ(path_data(svg).size(), 6u);  // before and after in three panels
}

TEST_F(FitReportTest, InterruptedWithoutMarkerEvaluation) {
  kelvin::FitReportData d = data();
  d.interrupted = true;
  d.markers.clear();
  d.tracks.clear();
  d.rms_before = d.rms_after = 0;
  d.lcurve.clear();
  d.history.clear();
  const std::string md = slurp(kelvin::write_fit_report(dir_.string(), d));
  EXPECT_NE(md.find("Marker RMS not evaluated"), std::string::npos);
  EXPECT_NE(md.find("**Interrupted.**"), std::string::npos);
  EXPECT_EQ(md.find("## Markers"), std::string::npos);
  EXPECT_EQ(md.find("## L-curve"), std::string::npos);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);
}

// --resume continues from the saved state exactly: parameters to the last bit, and
// the solver tolerances of the stage the loop was in.
TEST(FitState, RoundTripsExactlyWithTheToleranceScale) {
  const fs::path dir = fs::temp_directory_path() / fmt::format("kelvin-fit-state-{}", getpid());
  fs::create_directories(dir);
  const std::string path = (dir / "fit-state.yaml").string();
  kelvin::FitState s;
  s.scenario = "/data/bar.yaml";
  s.labels = {"elastic.mu", "viscous.nu"};
  s.start = Eigen::Vector2d(std::log(1.5e5), std::log(40.0));
  s.best = Eigen::Vector2d(std::log(3e5) + 1e-13, 0.1 + 0.2);
  s.best_objective = 1.0 / 3.0;
  s.best_rms = 2e-6 / 7;
  s.evaluations = 42;
  s.iterations = 17;
  s.failures = 3;
  s.seconds = 12.5;
  s.tolerance_scale = 0.01;
  kelvin::write_fit_state(path, s);
  const kelvin::FitState r = kelvin::read_fit_state(path);
  EXPECT_EQ(r.scenario, s.scenario);
  EXPECT_EQ(r.labels, s.labels);
  EXPECT_EQ(r.start, s.start);
  EXPECT_EQ(r.best, s.best);
  EXPECT_EQ(r.best_objective, s.best_objective);
  EXPECT_EQ(r.best_rms, s.best_rms);
  EXPECT_EQ(r.evaluations, 42);
  EXPECT_EQ(r.iterations, 17);
  EXPECT_EQ(r.failures, 3);
  EXPECT_EQ(r.tolerance_scale, 0.01);

  // A state saved before tolerances could be tightened resumes at the scenario's.
  std::string text;
  {
    std::ifstream in(path);
    for (std::string line; std::getline(in, line);)
      if (line.rfind("tolerance_scale", 0) != 0) text += line + "\n";
  }
  std::ofstream(path) << text;
  EXPECT_EQ(kelvin::read_fit_state(path).tolerance_scale, 1.0);

  // Cut in the middle (a copy that ran out of disk): named as truncated, not "line 0".
  kelvin::write_fit_state(path, s);
  {
    std::ifstream in(path);
    const std::string whole((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(path) << whole.substr(0, whole.find("best_objective"));
  }
  try {
    kelvin::read_fit_state(path);
    ADD_FAILURE() << "a truncated state was accepted";
  } catch (const kelvin::Error& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("line 0"), std::string::npos) << e.what();
  }

  std::ofstream(path) << "scenario: [unclosed\n";
  try {
    kelvin::read_fit_state(path);
    ADD_FAILURE() << "a malformed state was accepted";
  } catch (const kelvin::Error& e) {
    EXPECT_NE(std::string(e.what()).find(path + ": line "), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

}  // namespace
