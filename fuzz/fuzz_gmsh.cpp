// A Gmsh mesh file (2.2 or 4.1, ASCII or binary) read and validated.
#include "engine/mesh.hpp"
#include "fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = kelvin::fuzz::write_input("mesh.msh", data, size);
  kelvin::fuzz::expect_refusal_or_success([&] { kelvin::validate_mesh(kelvin::read_mesh(path)); });
  return 0;
}
