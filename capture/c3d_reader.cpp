#include "capture/c3d_reader.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <optional>

#include "base/error.hpp"
#include "engine/input_size.hpp"

namespace kelvin {
namespace {

enum class Processor { kIntel = 84, kDec = 85, kMips = 86 };

const char* processor_name(Processor p) {
  switch (p) {
    case Processor::kIntel:
      return "Intel";
    case Processor::kDec:
      return "DEC";
    case Processor::kMips:
      return "MIPS";
  }
  return "?";
}

/// The file's bytes with the processor's number formats; every read is bounds-checked
/// and names the byte offset it failed at.
class Bytes {
 public:
  Bytes(std::string path, std::vector<unsigned char> data)
      : path_(std::move(path)), data_(std::move(data)) {}
  size_t size() const { return data_.size(); }
  Processor processor = Processor::kIntel;

  void need(size_t at, size_t n, const char* what) const {
    if (at > data_.size() || n > data_.size() - at)
      throw Error(
          fmt::format("{}: truncated C3D file: {} at byte {} needs {} bytes, the file has {}",
                      path_, what, at, n, data_.size()));
  }
  uint8_t u8(size_t at) const {
    need(at, 1, "a byte");
    return data_[at];
  }
  int8_t i8(size_t at) const { return static_cast<int8_t>(u8(at)); }
  uint16_t u16(size_t at) const {
    need(at, 2, "a 16-bit word");
    const uint16_t a = data_[at], b = data_[at + 1];
    return processor == Processor::kMips ? static_cast<uint16_t>(a << 8 | b)
                                         : static_cast<uint16_t>(b << 8 | a);
  }
  int16_t i16(size_t at) const { return static_cast<int16_t>(u16(at)); }
  float f32(size_t at) const {
    need(at, 4, "a float");
    const unsigned char* b = &data_[at];
    uint32_t bits = 0;
    if (processor == Processor::kMips) {
      bits = uint32_t(b[0]) << 24 | uint32_t(b[1]) << 16 | uint32_t(b[2]) << 8 | b[3];
    } else if (processor == Processor::kIntel) {
      bits = uint32_t(b[3]) << 24 | uint32_t(b[2]) << 16 | uint32_t(b[1]) << 8 | b[0];
    } else {
      // VAX F_floating: two little-endian words, the first holding sign, exponent
      // (excess 128) and the high mantissa; value 0.1f × 2^(e − 128).
      const uint32_t hi = uint32_t(b[1]) << 8 | b[0], lo = uint32_t(b[3]) << 8 | b[2];
      const uint32_t word = hi << 16 | lo;
      const int e = static_cast<int>(word >> 23 & 0xff);
      if (e == 0) return 0.0f;  // zero (or VAX's reserved operand with the sign set)
      const double mantissa = 1.0 + static_cast<double>(word & 0x7fffff) / (1 << 23);
      const double v = std::ldexp(mantissa, e - 129);
      return static_cast<float>((word >> 31) ? -v : v);
    }
    float f;
    std::memcpy(&f, &bits, 4);
    return f;
  }
  std::string chars(size_t at, size_t n) const {
    need(at, n, "text");
    return std::string(reinterpret_cast<const char*>(&data_[at]), n);
  }

 private:
  std::string path_;
  std::vector<unsigned char> data_;
};

struct Parameter {
  int type = 0;           // −1 char, 1 byte, 2 int16, 4 float
  std::vector<int> dims;  // first dimension varies fastest
  size_t data = 0;        // byte offset of the values
  size_t count() const {
    size_t n = 1;
    for (int d : dims) n *= static_cast<size_t>(d);
    return n;
  }
};

std::string upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(" \t\r\n\0", 0, 5);
  if (a == std::string::npos) return "";
  const auto b = s.find_last_not_of(" \t\r\n\0", std::string::npos, 5);
  return s.substr(a, b - a + 1);
}

/// Reads every parameter of the parameter section into "GROUP:NAME" entries.
std::map<std::string, Parameter> read_parameters(const Bytes& f, size_t start,
                                                 const std::string& path) {
  std::map<int, std::string> groups;
  std::vector<std::pair<int, std::pair<std::string, Parameter>>> members;
  const size_t blocks = f.u8(start + 2);
  const size_t end = std::min(f.size(), start + 512 * std::max<size_t>(blocks, 1));
  size_t at = start + 4;
  for (int guard = 0; at + 2 <= end && guard < 100000; ++guard) {
    const int length = std::abs(static_cast<int>(f.i8(at)));
    const int id = f.i8(at + 1);
    if (length == 0 || id == 0) break;
    const std::string name = upper(trim(f.chars(at + 2, length)));
    const size_t link = at + 2 + length;
    const int next = f.i16(link);
    if (id < 0) {
      groups[-id] = name;
    } else {
      Parameter p;
      p.type = f.i8(link + 2);
      const int ndims = f.u8(link + 3);
      if (p.type != -1 && p.type != 1 && p.type != 2 && p.type != 4)
        throw Error(
            fmt::format("{}: C3D parameter '{}' at byte {} has data type {} (valid: -1, "
                        "1, 2, 4)",
                        path, name, at, p.type));
      for (int k = 0; k < ndims; ++k) p.dims.push_back(f.u8(link + 4 + k));
      p.data = link + 4 + ndims;
      f.need(p.data, p.count() * static_cast<size_t>(std::abs(p.type)), "a parameter's values");
      members.push_back({id, {name, p}});
    }
    if (next <= 0) break;
    at = link + static_cast<size_t>(next);
  }
  std::map<std::string, Parameter> out;
  for (auto& [id, entry] : members)
    out[(groups.count(id) ? groups[id] : fmt::format("GROUP{}", id)) + ":" + entry.first] =
        entry.second;
  return out;
}

class Parameters {
 public:
  Parameters(const Bytes& f, std::map<std::string, Parameter> p) : f_(f), p_(std::move(p)) {}
  const Parameter* find(const std::string& key) const {
    const auto it = p_.find(key);
    return it == p_.end() ? nullptr : &it->second;
  }
  /// The k-th number of a numeric parameter.
  std::optional<double> number(const std::string& key, size_t k = 0) const {
    const Parameter* p = find(key);
    if (!p || p->type == -1 || k >= p->count()) return std::nullopt;
    if (p->type == 1) return static_cast<double>(f_.u8(p->data + k));
    if (p->type == 2) return static_cast<double>(f_.i16(p->data + 2 * k));
    return static_cast<double>(f_.f32(p->data + 4 * k));
  }
  /// The strings of a character array (dims: length, count).
  std::vector<std::string> strings(const std::string& key) const {
    const Parameter* p = find(key);
    if (!p || p->type != -1) return {};
    if (p->dims.size() < 2) return {trim(f_.chars(p->data, p->count()))};
    const size_t len = static_cast<size_t>(p->dims[0]), n = p->count() / std::max<size_t>(len, 1);
    std::vector<std::string> out;
    for (size_t k = 0; k < n; ++k) out.push_back(trim(f_.chars(p->data + k * len, len)));
    return out;
  }

 private:
  const Bytes& f_;
  std::map<std::string, Parameter> p_;
};

double metres_per(const std::string& unit, const std::string& path) {
  const std::string u = upper(trim(unit));
  if (u.empty() || u == "MM") return 1e-3;  // the format's customary unit
  if (u == "M") return 1;
  if (u == "CM") return 1e-2;
  if (u == "IN") return 0.0254;
  throw Error(fmt::format("{}: C3D POINT:UNITS is '{}' (known: mm, cm, m, in)", path, unit));
}

}  // namespace

Capture read_c3d(const std::string& path) {
  check_data_file(path, "C3D file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(fmt::format("{}: cannot open the C3D file", path));
  std::vector<unsigned char> data((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
  Bytes f(path, std::move(data));
  if (f.size() < 512 || f.u8(1) != 0x50)
    throw Error(fmt::format("{}: not a C3D file (its second byte is not the key 0x50)", path));
  const size_t param_start = 512 * (static_cast<size_t>(std::max<int>(f.u8(0), 1)) - 1);
  f.need(param_start, 4, "the parameter section's header");
  const int proc = f.u8(param_start + 3);
  if (proc != 84 && proc != 85 && proc != 86)
    throw Error(fmt::format("{}: C3D processor type {} at byte {} (84 Intel, 85 DEC, 86 MIPS)",
                            path, proc, param_start + 3));
  f.processor = static_cast<Processor>(proc);

  // The header's words (1-based in the format's documentation).
  const auto word = [&](int k) { return f.u16(2 * static_cast<size_t>(k - 1)); };
  const Parameters P(f, read_parameters(f, param_start, path));
  int points = P.number("POINT:USED") ? static_cast<uint16_t>(*P.number("POINT:USED")) : word(2);
  const int analog_per_frame = word(3);
  long first = word(4), last = word(5);
  // TRIAL:ACTUAL_*_FIELD hold two words (low, high) for captures past 65535 frames.
  if (const Parameter* a = P.find("TRIAL:ACTUAL_START_FIELD"); a && a->type == 2 && a->count() >= 2)
    first = f.u16(a->data) + 65536L * f.u16(a->data + 2);
  if (const Parameter* a = P.find("TRIAL:ACTUAL_END_FIELD"); a && a->type == 2 && a->count() >= 2)
    last = f.u16(a->data) + 65536L * f.u16(a->data + 2);
  long frames = last - first + 1;
  if (const auto n = P.number("POINT:FRAMES"); n && frames <= 0)
    frames = static_cast<long>(*n < 0 ? *n + 65536 : *n);
  const float header_scale = f.f32(2 * 6);
  const double scale = P.number("POINT:SCALE").value_or(header_scale);
  const bool floats = scale < 0;
  double rate = P.number("POINT:RATE").value_or(f.f32(2 * 10));
  const size_t data_block =
      P.number("POINT:DATA_START") ? static_cast<uint16_t>(*P.number("POINT:DATA_START")) : word(9);
  if (points < 0 || frames <= 0 || !(rate > 0) || data_block < 2)
    throw Error(fmt::format(
        "{}: C3D header inconsistent: {} points, frames {}..{}, rate {:g} Hz, data block {}", path,
        points, first, last, rate, data_block));
  const double unit =
      metres_per(P.strings("POINT:UNITS").empty() ? "" : P.strings("POINT:UNITS")[0], path);

  std::vector<std::string> labels = P.strings("POINT:LABELS");
  for (int k = 2; static_cast<int>(labels.size()) < points; ++k) {
    const auto more = P.strings(fmt::format("POINT:LABELS{}", k));
    if (more.empty()) break;
    labels.insert(labels.end(), more.begin(), more.end());
  }
  labels.resize(std::max<size_t>(labels.size(), static_cast<size_t>(points)));
  labels.resize(static_cast<size_t>(points));
  Capture c;
  c.rate = rate;
  c.units = P.strings("POINT:UNITS").empty() ? "mm" : P.strings("POINT:UNITS")[0];
  c.format = fmt::format("C3D ({}, {})", processor_name(f.processor), floats ? "float" : "integer");
  std::map<std::string, int> seen;
  for (int i = 0; i < points; ++i) {
    std::string name = track_name(labels[i].empty() ? fmt::format("point{}", i + 1) : labels[i]);
    if (seen[name]++) name += fmt::format("_{}", seen[name]);
    c.markers.names.push_back(name);
  }

  const size_t word_bytes = floats ? 4 : 2;
  const size_t frame_bytes = word_bytes * (4 * static_cast<size_t>(points) + analog_per_frame);
  const size_t start = 512 * (data_block - 1);
  if (start + frame_bytes * static_cast<size_t>(frames) > f.size()) {
    const long whole =
        frame_bytes ? static_cast<long>((f.size() - std::min(start, f.size())) / frame_bytes) : 0;
    throw Error(fmt::format("{}: truncated C3D file: {} frames of {} points announced, {} present",
                            path, frames, points, whole));
  }
  c.markers.xyz.setConstant(3 * points, frames, std::numeric_limits<double>::quiet_NaN());
  c.markers.times.resize(static_cast<size_t>(frames));
  const double s = floats ? 1.0 : std::abs(scale);
  for (long k = 0; k < frames; ++k) {
    c.markers.times[static_cast<size_t>(k)] = static_cast<double>(k) / rate;
    size_t at = start + static_cast<size_t>(k) * frame_bytes;
    for (int i = 0; i < points; ++i, at += 4 * word_bytes) {
      double v[4];
      for (int a = 0; a < 4; ++a)
        v[a] = floats ? f.f32(at + 4 * a) : static_cast<double>(f.i16(at + 2 * a));
      // The fourth word packs camera mask and residual; negative marks an invalid point.
      const bool valid =
          floats ? v[3] >= 0 && std::isfinite(v[0] + v[1] + v[2]) : static_cast<int16_t>(v[3]) >= 0;
      if (valid)
        for (int a = 0; a < 3; ++a) c.markers.xyz(3 * i + a, k) = v[a] * s * unit;
    }
  }
  return c;
}

}  // namespace kelvin
