// A plugin with the right ABI version but no model table.
#include <cstdint>

#include "materials/plugin_abi.h"

extern "C" __attribute__((visibility("default"))) uint32_t kelvin_plugin_abi_version(void) {
  return KELVIN_PLUGIN_ABI_VERSION;
}
