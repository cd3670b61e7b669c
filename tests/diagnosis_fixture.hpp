#pragma once
// The diagnosis cases of the tests: a shaken bar whose captured tracks were simulated
// from a known truth (an effect the nominal model lacks) with noise, and a held-out
// motion of it at other frequencies.
#include "test_support.hpp"

namespace kelvin::test {

inline const std::string kNominal = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 0.8e5 }
  viscous: { model: newtonian, nu: 30 })";

// Captured at 1 kHz: the noise estimate assumes the model error is slow against the
// frame rate (it cancels (2π f Δt)³ of it), and the bar is shaken at 13 and 17 Hz.
inline std::string bar(const std::string& material, const std::string& tail, double end = 0.1,
                       const std::string& mesh_keys = "", const std::string& solver_keys = "") {
  test::ShakenBar b;
  b.mesh_keys = mesh_keys;
  b.solver_keys = solver_keys;
  b.material = material;
  b.end = end;
  b.output_rate = 1000;
  b.rtol = 1e-7;
  b.atol = 1e-11;
  b.tail = tail;
  return test::shaken_bar_yaml(b);
}

/// A diagnosis scenario for the shaken bar whose tracks came from `truth` (with
/// noise), a held-out motion of the same bar at other frequencies.
inline fs::path diagnosis_case(
    const fs::path& dir, const std::string& truth, unsigned seed,
    const std::string& candidates = "stiffening, drag, sync_lag, marker_offset",
    const std::string& more = "", bool truth_refined = false) {
  // The specimen's own discretisation: the same box, each tetrahedron split into
  // eight (a truth the nominal mesh cannot reach).
  const std::string mesh_keys = truth_refined ? ", refine: 1" : "";
  const std::string solver_keys;
  const std::string train = test::noisy_tracks(
      test::simulate_tracks(dir, "truth-train",
                            bar(truth, test::kShakenBarMarkers, 0.1, mesh_keys, solver_keys)),
      dir / "train.csv", 1e-5, seed);
  test::ShakenBar h;
  h.mesh_keys = mesh_keys;
  h.solver_keys = solver_keys;
  h.material = truth;
  h.end = 0.1;
  h.output_rate = 1000;
  h.rtol = 1e-7;
  h.atol = 1e-11;
  h.frequency_y = 11;
  h.frequency_z = 19;
  h.amplitude_y = 0.002;
  h.amplitude_z = 0.003;
  h.tail = test::kShakenBarMarkers;
  const std::string held =
      test::noisy_tracks(test::simulate_tracks(dir, "truth-heldout", test::shaken_bar_yaml(h)),
                         dir / "heldout.csv", 1e-5, seed + 1);
  h.material = kNominal;
  h.mesh_keys = h.solver_keys = "";
  h.tail = test::kShakenBarMarkers + "\n  observed: " + held + "\n";
  test::write_text(dir / "heldout.yaml", test::shaken_bar_yaml(h));
  test::write_text(dir / "train.yaml",
                   bar(kNominal, test::kShakenBarMarkers + "\n  observed: " + train +
                                     "\nfit:\n  parameters: [elastic.mu, viscous.nu]\n"
                                     "  max_evaluations: 30\ndiagnose:\n  candidates: [" +
                                     candidates +
                                     "]\n  refits: 2\n"
                                     "  validate: [heldout.yaml]\n" +
                                     more));
  return dir / "train.yaml";
}

inline  // The truth of the drag tests: the nominal bar in air that drags it (−cρv).
    const std::string kWithDrag = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous:
    - { model: newtonian, nu: 20 }
    - { model: drag, c: 40 })";

}  // namespace kelvin::test
