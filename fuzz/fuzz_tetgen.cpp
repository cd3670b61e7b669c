// A TetGen mesh: the input holds the .node file, a line "#ele", then the .ele file.
#include <string_view>

#include "engine/mesh.hpp"
#include "fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view all(reinterpret_cast<const char*>(data), size);
  const size_t cut = all.find("#ele\n");
  const std::string_view node = all.substr(0, cut),
                         ele = cut == std::string_view::npos ? "" : all.substr(cut + 5);
  kelvin::fuzz::write_input("mesh.ele", reinterpret_cast<const uint8_t*>(ele.data()), ele.size());
  const std::string path = kelvin::fuzz::write_input(
      "mesh.node", reinterpret_cast<const uint8_t*>(node.data()), node.size());
  kelvin::fuzz::expect_refusal_or_success([&] { kelvin::validate_mesh(kelvin::read_mesh(path)); });
  return 0;
}
