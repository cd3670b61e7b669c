#include "capture/capture.hpp"

#include <fmt/format.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <fstream>

#include "base/error.hpp"
#include "capture/c3d_reader.hpp"
#include "capture/motive_csv_reader.hpp"
#include "engine/input_size.hpp"

namespace kelvin {

std::string track_name(const std::string& label) {
  std::string s = label;
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '.' && c != ':') c = '_';
  return s;
}

Capture read_capture(const std::string& path) {
  check_data_file(path, "capture file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(fmt::format("{}: cannot open ({})", path, std::strerror(errno)));
  char head[2] = {0, 0};
  in.read(head, 2);
  if (in.gcount() == 2 && static_cast<unsigned char>(head[1]) == 0x50) return read_c3d(path);
  return read_motive_csv(path);
}

}  // namespace kelvin
