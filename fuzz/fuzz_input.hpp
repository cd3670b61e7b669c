#pragma once
/// \file
/// What every fuzz target shares: the input written to a file (kelvin's readers take
/// paths), and the rule that a refusal is a kelvin::Error. Any other exception, a
/// crash, a leak-free hang past libFuzzer's -timeout or an allocation past
/// -rss_limit_mb is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "base/error.hpp"

namespace kelvin::fuzz {

/// A scratch directory of this process, for the input files.
inline const std::filesystem::path& scratch() {
  static const std::filesystem::path dir = [] {
    auto d = std::filesystem::temp_directory_path() / ("kelvin-fuzz-" + std::to_string(getpid()));
    std::filesystem::create_directories(d);
    return d;
  }();
  return dir;
}

/// Writes bytes to scratch()/name and returns its path.
inline std::string write_input(const std::string& name, const uint8_t* data, size_t size) {
  const std::string path = (scratch() / name).string();
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

/// Runs a reader; a kelvin::Error is the refusal every bad input must get.
template <class Read>
void expect_refusal_or_success(Read read) {
  try {
    read();
  } catch (const Error&) {
  }
}

}  // namespace kelvin::fuzz
