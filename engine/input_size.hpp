#pragma once
// One size limit for every data file kelvin reads (meshes, CSV, captures): a file
// beyond it is refused before reading, so a wrong or hostile file cannot take the
// machine's memory. A capture or mesh this machine can simulate is far smaller.
#include <fmt/format.h>

#include <cstdint>
#include <filesystem>
#include <string>

#include "base/error.hpp"

namespace kelvin {

inline constexpr std::uintmax_t kMaxDataFileBytes = std::uintmax_t{512} << 20;

/// Throws unless `path` is a regular file no larger than kMaxDataFileBytes.
inline void check_data_file(const std::string& path, const char* what) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw Error(fmt::format("{}: is a directory, not a {}", path, what));
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && size > kMaxDataFileBytes)
    throw Error(fmt::format("{}: {} MiB is more than kelvin reads as a {} (at most {} MiB)", path,
                            size >> 20, what, kMaxDataFileBytes >> 20));
}

}  // namespace kelvin
