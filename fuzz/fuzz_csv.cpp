// kelvin's CSV formats: the first byte picks the reader (marker rest positions,
// marker tracks, clamp motion), the rest is the file.
#include "engine/csv.hpp"
#include "engine/rigid_motion.hpp"
#include "fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string path = kelvin::fuzz::write_input("input.csv", data + 1, size - 1);
  kelvin::fuzz::expect_refusal_or_success([&] {
    switch (data[0] % 3) {
      case 0:
        kelvin::read_marker_rest(path);
        break;
      case 1:
        kelvin::read_marker_tracks(path);
        break;
      default:
        kelvin::read_clamp_csv(path);
    }
  });
  return 0;
}
