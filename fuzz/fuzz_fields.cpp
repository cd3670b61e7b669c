// A `material.fields` CSV (per-element values) under a fixed scenario whose box mesh
// has 6 × 2 × 2 × 6 = 144 elements.
#include "fuzz/fuzz_input.hpp"
#include "yaml/scenario.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string fields = kelvin::fuzz::write_input("fields.csv", data, size);
  static const std::string yaml = R"(
mesh: { generate: box, lo: [0, 0, 0], hi: [0.06, 0.02, 0.02], element_size: 0.01 }
material:
  density: 1000
  elastic: { model: neo-hookean, lambda: 1.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 1 }
  fields: fields.csv
clamps: [ { select: { plane: { axis: x, at: 0 } } } ]
)";
  const std::string path = kelvin::fuzz::write_input(
      "fields.yaml", reinterpret_cast<const uint8_t*>(yaml.data()), yaml.size());
  (void)fields;
  kelvin::fuzz::expect_refusal_or_success([&] { kelvin::load_scenario(path); });
  return 0;
}
