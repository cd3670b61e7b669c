#pragma once
// The joint fit the MPI tests run: the shaken bar of test_support.hpp in three
// motions (three experiments, so that two ranks own unequal shares), its tracks
// simulated with known parameters and the fit started 1.6× off in μ and ν.
#include "test_support.hpp"

namespace kelvin::test {

inline const std::string kMpiTruth = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 6.0e5, mu: 3.0e5 }
  viscous: { model: newtonian, nu: 20 })";
inline const std::string kMpiStart = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 6.0e5, mu: 1.9e5 }
  viscous: { model: newtonian, nu: 32 })";

/// Writes motion0.yaml (the fitted scenario, with `fit_keys` in its fit section),
/// motion1.yaml and motion2.yaml to `dir` and returns the first's path. Motion k is
/// shaken at 17 + 4k Hz along y; `solver_keys` go into motion 1's solver section.
inline std::string write_three_motion_fit(const fs::path& dir, const std::string& fit_keys,
                                          const std::string& solver_keys = "") {
  for (int k = 0; k < 3; ++k) {
    ShakenBar bar;
    bar.name = fmt::format("motion{}", k);
    bar.frequency_y = 17 + 4 * k;
    bar.end = 0.12;
    bar.rtol = 1e-7;
    bar.atol = 1e-11;
    bar.material = kMpiTruth.substr(1);
    const std::string truth =
        simulate_tracks(dir, fmt::format("truth{}", k), shaken_bar_yaml(bar) + kShakenBarMarkers);
    bar.material = kMpiStart.substr(1);
    bar.rtol = 1e-5;
    bar.atol = 1e-9;
    if (k == 1) bar.solver_keys = solver_keys;
    bar.tail = kShakenBarMarkers + "\n  observed: " + truth + "\n";
    if (k == 0)
      bar.tail +=
          "fit:\n  parameters: [elastic.mu, viscous.nu]\n  experiments: [motion1.yaml, "
          "motion2.yaml]\n" +
          fit_keys;
    write_text(dir / fmt::format("motion{}.yaml", k), shaken_bar_yaml(bar));
  }
  return (dir / "motion0.yaml").string();
}

}  // namespace kelvin::test
