// A scenario file through the whole loader and its checks (yaml/scenario_loader.cpp):
// every section, the mesh and CSV files it names, the fit and diagnose sections.
#include "fuzz/fuzz_input.hpp"
#include "yaml/scenario.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = kelvin::fuzz::write_input("scenario.yaml", data, size);
  kelvin::fuzz::expect_refusal_or_success([&] { kelvin::load_scenario(path); });
  return 0;
}
