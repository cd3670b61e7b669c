// Motion-capture exports: the first byte picks C3D (binary) or Motive CSV.
#include "capture/c3d_reader.hpp"
#include "capture/motive_csv_reader.hpp"
#include "fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const bool c3d = data[0] % 2 == 0;
  const std::string path =
      kelvin::fuzz::write_input(c3d ? "capture.c3d" : "capture.csv", data + 1, size - 1);
  kelvin::fuzz::expect_refusal_or_success([&] {
    if (c3d)
      kelvin::read_c3d(path);
    else
      kelvin::read_motive_csv(path);
  });
  return 0;
}
