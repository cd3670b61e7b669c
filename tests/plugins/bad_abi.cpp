// A plugin built for a future ABI major version: kelvin must refuse it by name.
#include <cstdint>

#include "materials/plugin_abi.h"

extern "C" __attribute__((visibility("default"))) uint32_t kelvin_plugin_abi_version(void) {
  return (KELVIN_PLUGIN_ABI_MAJOR + 1u) << 16;
}
extern "C" __attribute__((visibility("default"))) int kelvin_plugin_materials(
    const kelvin_material_desc** out) {
  *out = nullptr;
  return 0;
}
