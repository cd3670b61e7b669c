#pragma once
// The benchmark bar of bench_fit and bench_work_precision: 50 × 20 × 20 mm, 120 tets,
// clamped at x = 0 and shaken at 17 and 13 Hz, three markers; strongly damped
// (power-law viscosity), the kind of body on which BDF orders above 2 pay.
#include <fmt/format.h>

#include <string>

namespace kelvin::bench {

/// Power-law truth of the bar's tracks: λ 6e5, μ 3e5, ν 20, h 0.8.
inline const char* kBarTruthMaterial = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 6.0e5, mu: 3.0e5 }
  viscous: { model: power-law, nu: 20, h: 0.8 })";

/// The bar's scenario text: `material` (the lines under `material:`), its duration
/// and marker rate, a `solver:` mapping (e.g. "{ rtol: 1e-6, atol: 1e-10 }") and
/// `tail`, appended under `markers:` (e.g. an observed track and a fit section).
inline std::string bar_scenario(const std::string& material, double duration, double rate,
                                const std::string& solver, const std::string& tail) {
  return fmt::format(R"(
name: bench-bar
mesh: {{ generate: box, lo: [0, 0, 0], hi: [0.05, 0.02, 0.02], element_size: 0.01 }}
material:
{}
gravity: [0, 0, -9.81]
initial: static
clamps:
  - name: base
    select: {{ plane: {{ axis: x, at: 0 }} }}
    motion:
      sinusoids:
        translation:
          - {{ amplitude: 0.004, frequency: 17, phase: -1.5707963267948966, direction: [0, 1, 0] }}
          - {{ amplitude: 0.003, frequency: 13, phase: -1.5707963267948966, direction: [0, 0, 1] }}
time: {{ end: {}, output_rate: {} }}
solver: {}
markers:
  rest:
    - {{ name: tip, at: [0.05, 0.01, 0.01] }}
    - {{ name: tip_top, at: [0.05, 0.0, 0.02] }}
    - {{ name: mid, at: [0.025, 0.01, 0.02] }}
{})",
                     material, duration, rate, solver, tail);
}

}  // namespace kelvin::bench
