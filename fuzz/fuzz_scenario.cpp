// A scenario file through the whole loader and its checks (yaml/scenario_loader.cpp):
// every section, the mesh and CSV files it names, the fit and diagnose sections, and
// the probing section (probing/probing_settings.cpp) when there is one.
#include <string_view>

#include "fuzz/fuzz_input.hpp"
#include "probing/probing_settings.hpp"
#include "yaml/scenario.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = kelvin::fuzz::write_input("scenario.yaml", data, size);
  const bool probing =
      std::string_view(reinterpret_cast<const char*>(data), size).find("probing") !=
      std::string_view::npos;
  kelvin::fuzz::expect_refusal_or_success([&] {
    const kelvin::Scenario s = kelvin::load_scenario(path);
    if (probing) kelvin::load_probing(s);
  });
  return 0;
}
