// Loads (`loads:`): a force and an attached mass on the end of an axial bar make a
// spring–mass system with a known answer. With λ ≈ 0 (10⁻⁶ μ) the neo-Hookean bar is, at
// small strain, a ν = 0 solid with E = 2μ: axial stiffness k = EA/L, static
// extension F/k, and a step force from rest swings the tip between 0 and 2F/k at
// the fixed–mass bar's frequency ω = β √(k/m), β tan β = m/M (m the bar's mass,
// M the tip mass). A weight given as a mass under gravity equals the same force.
#include <gtest/gtest.h>

#include <cmath>

#include "base/error.hpp"
#include "engine/csv.hpp"
#include "tests/test_support.hpp"

using namespace kelvin;
using namespace kelvin::test;

namespace {

constexpr double kL = 0.1, kW = 0.01, kRho = 1000, kMu = 1e5;
constexpr double kE = 2 * kMu, kK = kE * kW * kW / kL;  // 200 N/m
constexpr double kBarMass = kRho * kL * kW * kW;        // 0.01 kg

/// A 100 × 10 × 10 mm bar clamped at x = 0, with `loads` (YAML list body) on its
/// free end face; markers on the four corners of that face.
std::string bar_yaml(const std::string& loads, const std::string& gravity,
                     const std::string& initial, double end, double rate) {
  return fmt::format(R"(
name: loaded-bar
mesh: {{ generate: box, lo: [0, 0, 0], hi: [{0}, {1}, {1}], element_size: 0.01 }}
material:
  density: {2}
  elastic: {{ model: neo-hookean, lambda: 0.1, mu: {3} }}
gravity: {4}
initial: {5}
clamps:
  - name: base
    select: {{ plane: {{ axis: x, at: 0 }} }}
loads:
{6}
markers:
  rest:
    - {{ name: a, at: [{0}, 0, 0] }}
    - {{ name: b, at: [{0}, {1}, 0] }}
    - {{ name: c, at: [{0}, 0, {1}] }}
    - {{ name: d, at: [{0}, {1}, {1}] }}
time: {{ end: {7}, output_rate: {8} }}
solver: {{ rtol: 1.0e-9, atol: 1.0e-14 }}
)",
                     kL, kW, kRho, kMu, gravity, initial, loads, end, rate);
}

/// The marker tracks of a run of `yaml`.
MarkerTracks run(const std::string& name, const std::string& yaml) {
  const fs::path dir = scratch("loads-" + name);
  write_text(dir / "s.yaml", yaml);
  SimulationOptions o;
  o.outdir = (dir / "out").string();
  const SimulationResult r = run_simulation(load_scenario((dir / "s.yaml").string()), o);
  EXPECT_TRUE(r.completed) << r.error;
  return read_marker_tracks((dir / "out" / "markers.csv").string());
}

/// β of the fixed–mass bar's first mode: β tan β = m/M, by Newton from the
/// spring–mass guess β² ≈ (m/M)/(1 + m/3M).
double fixed_mass_beta(double mass_ratio) {
  double b = std::sqrt(mass_ratio / (1 + mass_ratio / 3));
  for (int i = 0; i < 50; ++i) {
    const double f = b * std::tan(b) - mass_ratio;
    const double df = std::tan(b) + b / (std::cos(b) * std::cos(b));
    b -= f / df;
  }
  return b;
}

std::string end_face_load(const std::string& body) {
  return fmt::format("  - name: weight\n    select: {{ plane: {{ axis: x, at: {} }} }}\n    {}\n",
                     kL, body);
}

}  // namespace

/// Mean x of the loaded face's four corners at frame k: what equal shares of a force do work on.
double face_x(const MarkerTracks& t, int k) {
  return (t.xyz(0, k) + t.xyz(3, k) + t.xyz(6, k) + t.xyz(9, k)) / 4;
}

TEST(Loads, StaticExtensionUnderAnEndForceIsFOverK) {
  const double F = 0.02;  // strain 1e-3
  const MarkerTracks t = run("static", bar_yaml(end_face_load(fmt::format("force: [{}, 0, 0]", F)),
                                                "[0, 0, 0]", "static", 1e-3, 1000));
  const double u = face_x(t, 0) - kL;
  std::printf("  static end-face extension %.6e m, F/k = %.6e m\n", u, F / kK);
  // Uniform strain is exact in linear tets. Equal shares on the four corners differ
  // from a uniform traction by a self-equilibrated set that adds compliance one
  // element deep (0.5 % here); geometric nonlinearity adds ~strain (0.05 %).
  EXPECT_NEAR(u, F / kK, 0.01 * F / kK);
}

TEST(Loads, StepForceOnATipMassSwingsAtTheFixedMassBarFrequency) {
  const double F = 0.02, M = 0.1;  // M = 10 × the bar's mass
  const MarkerTracks s =
      run("swing-static", bar_yaml(end_face_load(fmt::format("force: [{}, 0, 0]", F)), "[0, 0, 0]",
                                   "static", 1e-3, 1000));
  // The mesh's own stiffness against this load pattern; the tip mass's inertia
  // loads the face in the same equal shares.
  const double delta = face_x(s, 0) - kL, k_mesh = F / delta;
  const double beta = fixed_mass_beta(kBarMass / M);
  const double period = 2 * M_PI / (beta * std::sqrt(k_mesh / kBarMass));
  const MarkerTracks t =
      run("swing", bar_yaml(end_face_load(fmt::format("force: [{}, 0, 0]\n    mass: {}", F, M)),
                            "[0, 0, 0]", "rest", 3.2 * period, 4000));
  // Upward crossings of the static position give the period; the peak gives 2F/k.
  std::vector<double> crossings;
  double peak = 0;
  for (int k = 1; k < static_cast<int>(t.times.size()); ++k) {
    const double a = face_x(t, k - 1) - kL - delta, b = face_x(t, k) - kL - delta;
    peak = std::max(peak, face_x(t, k) - kL);
    if (a < 0 && b >= 0)
      crossings.push_back(t.times[k - 1] + (t.times[k] - t.times[k - 1]) * a / (a - b));
  }
  ASSERT_GE(crossings.size(), 3u);
  const double measured = (crossings.back() - crossings.front()) / (crossings.size() - 1);
  std::printf(
      "  period %.6f s (fixed-mass bar at the mesh's stiffness %.6f s; without the tip mass "
      "the bar rings at %.4f s); peak %.5e m (2F/k %.5e m)\n",
      measured, period, 4 * kL / std::sqrt(kE / kRho), peak, 2 * delta);
  // The step also excites the second axial mode (10× faster, small): it shifts the
  // crossings by a fraction of its own period, which three periods average down.
  EXPECT_NEAR(measured, period, 1e-3 * period);
  EXPECT_NEAR(peak, 2 * delta, 0.01 * delta);
}

TEST(Loads, AWeightGivenAsAMassEqualsTheSameForceAtRest) {
  const double M = 0.05, g = 9.81;
  const MarkerTracks a = run("mass", bar_yaml(end_face_load(fmt::format("mass: {}", M)),
                                              fmt::format("[0, 0, {}]", -g), "static", 1e-3, 1000));
  const MarkerTracks b =
      run("force", bar_yaml(end_face_load(fmt::format("force: [0, 0, {}]", -M * g)),
                            fmt::format("[0, 0, {}]", -g), "static", 1e-3, 1000));
  const double sag = a.xyz(2, 0);  // corner a starts at z = 0
  std::printf("  static tip sag %.6e m (mass) vs %.6e m (force)\n", sag, b.xyz(2, 0));
  EXPECT_LT(sag, -1e-3);  // the weight bends the bar visibly
  EXPECT_NEAR(a.xyz(2, 0), b.xyz(2, 0), 1e-9 * std::abs(sag));
}

TEST(Loads, RefusedWithFileLineAndKey) {
  const fs::path dir = scratch("loads-errors");
  struct Case {
    std::string loads, expected;
  };
  const Case cases[] = {
      {"  - name: w\n    select: { plane: { axis: x, at: 0.1 } }\n",
       "loads[0]: give a force (N, total), a mass (kg, total) or both"},
      {"  - name: w\n    select: { plane: { axis: x, at: 0 } }\n    mass: 0.1\n",
       "loads[0].select: selects 4 node(s), all held by clamps"},
      {"  - name: w\n    select: { plane: { axis: x, at: 0.1 } }\n    mass: -1\n",
       "loads[0].mass: must not be negative"},
      {"  - name: w\n    select: { plane: { axis: x, at: 0.1 } }\n    mass: 1\n"
       "  - name: w\n    select: { plane: { axis: x, at: 0.1 } }\n    mass: 1\n",
       "loads[1].name: 'w' is already the name of another load"},
  };
  for (const Case& c : cases) {
    write_text(dir / "s.yaml", bar_yaml(c.loads, "[0, 0, 0]", "rest", 0.01, 100));
    try {
      load_scenario((dir / "s.yaml").string());
      ADD_FAILURE() << "accepted: " << c.loads;
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("s.yaml:"), std::string::npos) << m;
      EXPECT_NE(m.find(c.expected), std::string::npos) << m;
    }
  }
}
