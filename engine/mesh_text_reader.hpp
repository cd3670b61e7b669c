#pragma once
// Token reader shared by the ASCII mesh formats: tracks the 1-based line of every
// token so that errors name "file:line", and never reads past the end silently.
#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "base/error.hpp"
#include "engine/input_size.hpp"

namespace kelvin {

class MeshTextReader {
 public:
  explicit MeshTextReader(std::string path) : path_(std::move(path)) {
    check_data_file(path_, "mesh file");
    in_.open(path_);
    if (!in_) throw Error(fmt::format("{}: cannot open ({})", path_, std::strerror(errno)));
  }
  const std::string& path() const { return path_; }
  int line() const { return line_; }

  /// Next line (CR stripped, '#' comments removed when `comments`); false at EOF.
  bool next_line(std::string& out, bool comments = false) {
    while (std::getline(in_, out)) {
      ++line_;
      if (!out.empty() && out.back() == '\r') out.pop_back();
      if (comments) {
        const auto hash = out.find('#');
        if (hash != std::string::npos) out.erase(hash);
      }
      if (out.find_first_not_of(" \t") != std::string::npos || !comments) return true;
    }
    return false;
  }
  /// Next non-empty line, or an error saying what was expected.
  std::string require_line(const char* expected, bool comments = false) {
    std::string s;
    if (!next_line(s, comments))
      throw Error(
          fmt::format("{}:{}: unexpected end of file, expected {}", path_, line_, expected));
    return s;
  }
  [[noreturn]] void fail(const std::string& why) const {
    throw Error(fmt::format("{}:{}: {}", path_, line_, why));
  }
  /// A number read as a double that must be an id or a count: refused unless it is an
  /// integer within ±2e9 (casting a double beyond the integer range is undefined).
  long integer(double v, const char* what) const {
    if (!(std::abs(v) <= 2e9) || v != std::trunc(v))
      fail(fmt::format("{} {:g} is not an integer", what, v));
    return static_cast<long>(v);
  }

  /// Parses exactly `n` numbers (or at least n when `at_least`) from a line.
  template <class T>
  std::vector<T> numbers(const std::string& s, size_t n, const char* what, bool at_least = false) {
    std::vector<T> out;
    std::istringstream ss(s);
    std::string tok;
    while (ss >> tok) {
      char* end = nullptr;
      errno = 0;
      const double v = std::strtod(tok.c_str(), &end);
      if (*end != '\0' || errno == ERANGE || !std::isfinite(v))
        fail(fmt::format("'{}' is not a number (reading {})", tok, what));
      if constexpr (std::is_integral_v<T>) {
        // The range first: casting a double beyond long long is undefined behaviour.
        if (std::abs(v) > 2e9 || v != std::trunc(v))
          fail(fmt::format("'{}' is not an integer (reading {})", tok, what));
      }
      out.push_back(static_cast<T>(v));
    }
    if (at_least ? out.size() < n : out.size() != n)
      fail(fmt::format("expected {}{} values for {}, found {}", at_least ? "at least " : "", n,
                       what, out.size()));
    return out;
  }

 private:
  std::string path_;
  std::ifstream in_;
  int line_ = 0;
};

}  // namespace kelvin
