#include "yaml/yaml_util.hpp"

#include <fmt/format.h>
#include <yaml-cpp/depthguard.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

#include "base/error.hpp"

namespace kelvin::yamlutil {

size_t levenshtein(const std::string& a, const std::string& b) {
  std::vector<size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] != b[j - 1])});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string suggestion(const std::string& word, const std::vector<std::string>& candidates,
                       const std::string& what) {
  std::string best;
  size_t best_d = 3;
  for (const auto& c : candidates) {
    // Replacing every letter of a short name is no typo ('w' is not a slip for 'x').
    const size_t d = levenshtein(word, c);
    if (d < best_d && d < c.size()) best_d = d, best = c;
  }
  // A prefix ("elem" for "element_size") is as telling as a small typo.
  if (best.empty() && word.size() >= 2)
    for (const auto& c : candidates)
      if (c.rfind(word, 0) == 0 || word.rfind(c, 0) == 0) {
        best = c;
        break;
      }
  if (!best.empty()) return fmt::format("did you mean '{}'?", best);
  std::string list;
  for (const auto& c : candidates) list += (list.empty() ? "" : ", ") + c;
  return fmt::format("{}: {}", what, list);
}

std::string join(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

std::string index(const std::string& path, size_t i) {
  return fmt::format("{}[{}]", path, i);
}

Doc::Doc(const std::string& path) : file_(path) {
  dir_ = std::filesystem::path(path).parent_path().string();
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw Error(fmt::format("{}: is a directory, not a scenario file", path));
  std::ifstream probe(path);
  if (!probe) throw Error(fmt::format("{}: cannot open the scenario file", path));
  // A scenario names its data files; one this large is not a scenario, and parsing
  // it would take minutes and gigabytes.
  constexpr std::uintmax_t kMaxBytes = 4u << 20;
  if (const auto size = std::filesystem::file_size(path, ec); !ec && size > kMaxBytes)
    throw Error(
        fmt::format("{}: {:.1f} MB is not a scenario file (at most {} MB; large data "
                    "belong in the CSV and mesh files it names)",
                    path, size / 1e6, kMaxBytes >> 20));
  try {
    root_ = YAML::LoadFile(path);
  } catch (const YAML::DeepRecursion& e) {
    fail(e.mark, "",
         fmt::format("YAML nested {} levels deep, the reader's limit (a scenario needs a "
                     "handful)",
                     e.depth()));
  } catch (const YAML::ParserException& e) {
    fail(e.mark, "", "YAML syntax error: " + e.msg);
  } catch (const YAML::Exception& e) {
    fail(e.mark, "", "YAML error: " + e.msg);
  }
  if (!root_.IsDefined() || root_.IsNull())
    throw Error(fmt::format("{}: the scenario file is empty", path));
  require_map(root_, "");
}

void Doc::fail(const YAML::Mark& at, const std::string& path, const std::string& why) const {
  const std::string where =
      at.line >= 0 ? fmt::format("{}:{}:{}", file_, at.line + 1, at.column + 1) : file_;
  throw Error(path.empty() ? fmt::format("{}: {}", where, why)
                           : fmt::format("{}: {}: {}", where, path, why));
}

void Doc::fail(const YAML::Node& at, const std::string& path, const std::string& why) const {
  fail(at.IsDefined() ? at.Mark() : YAML::Mark::null_mark(), path, why);
}

void Doc::require_map(const YAML::Node& node, const std::string& path) const {
  if (!node.IsMap())
    fail(node, path.empty() ? "(top level)" : path,
         node.IsNull() ? "is empty; expected a mapping of keys"
                       : "expected a mapping of keys (key: value)");
  // yaml-cpp reads a merge key as a key named "<<", so its keys would go missing.
  for (auto it = node.begin(); it != node.end(); ++it)
    if (it->first.IsScalar() && it->first.Scalar() == "<<")
      fail(it->first.Mark(), join(path, "<<"),
           "YAML merge keys are not supported; write the keys out (an alias '*name' "
           "of a whole value works)");
}

void Doc::require_sequence(const YAML::Node& node, const std::string& path) const {
  if (!node.IsSequence()) fail(node, path, "expected a list ([a, b, ...] or '- ' items)");
}

void Doc::check_keys(const YAML::Node& map, const std::string& path,
                     const std::vector<std::string>& allowed) const {
  require_map(map, path);
  std::set<std::string> seen;
  for (auto it = map.begin(); it != map.end(); ++it) {
    if (!it->first.IsScalar()) fail(it->first.Mark(), path, "keys must be plain names");
    const std::string key = it->first.Scalar();
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end())
      fail(it->first.Mark(), join(path, key),
           fmt::format("unknown key '{}'; {}", key, suggestion(key, allowed)));
    if (!seen.insert(key).second) fail(it->first.Mark(), join(path, key), "is given twice");
  }
}

YAML::Node Doc::required(const YAML::Node& map, const std::string& path,
                         const std::string& key) const {
  YAML::Node v = map[key];
  if (!v.IsDefined())
    fail(map, join(path, key),
         fmt::format("missing required key '{}'{}", key,
                     path.empty() ? "" : fmt::format(" in '{}'", path)));
  return v;
}

YAML::Mark Doc::key_mark(const YAML::Node& map, const std::string& key) const {
  for (auto it = map.begin(); it != map.end(); ++it)
    if (it->first.IsScalar() && it->first.Scalar() == key) return it->first.Mark();
  return map.Mark();
}

double Doc::number(const YAML::Node& node, const std::string& path) const {
  if (!node.IsScalar())
    fail(node, path,
         node.IsNull() ? "needs a number (nothing given)"
                       : "must be a number, not a list or mapping");
  double v = 0;
  try {
    v = node.as<double>();
  } catch (const YAML::Exception&) {
    fail(node, path, fmt::format("must be a number (got '{}')", node.Scalar()));
  }
  if (!std::isfinite(v)) fail(node, path, fmt::format("must be finite (got {})", node.Scalar()));
  return v;
}

long Doc::integer(const YAML::Node& node, const std::string& path) const {
  const double v = number(node, path);
  if (v != std::floor(v))
    fail(node, path, fmt::format("must be a whole number (got {})", node.Scalar()));
  if (std::abs(v) > 9e15)
    fail(node, path, fmt::format("{} is too large (at most 9e15)", node.Scalar()));
  return static_cast<long>(v);
}

std::string Doc::string(const YAML::Node& node, const std::string& path) const {
  if (!node.IsScalar())
    fail(node, path, node.IsNull() ? "needs a value (nothing given)" : "must be a plain string");
  return node.Scalar();
}

std::string Doc::choice(const YAML::Node& node, const std::string& path,
                        const std::vector<std::string>& choices) const {
  const std::string s = string(node, path);
  if (std::find(choices.begin(), choices.end(), s) == choices.end())
    fail(node, path,
         fmt::format("'{}' is not valid; {}", s, suggestion(s, choices, "expected one of")));
  return s;
}

Eigen::Vector3d Doc::vec3(const YAML::Node& node, const std::string& path) const {
  if (!node.IsSequence() || node.size() != 3)
    fail(node, path, "must be a list of three numbers [x, y, z]");
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) v[i] = number(node[i], index(path, i));
  return v;
}

double Doc::positive(const YAML::Node& node, const std::string& path,
                     const std::string& unit) const {
  const double v = number(node, path);
  if (v <= 0)
    fail(node, path,
         fmt::format("must be positive (got {:g}{}{})", v, unit.empty() ? "" : " ", unit));
  return v;
}

double Doc::non_negative(const YAML::Node& node, const std::string& path,
                         const std::string& unit) const {
  const double v = number(node, path);
  if (v < 0)
    fail(node, path,
         fmt::format("must not be negative (got {:g}{}{})", v, unit.empty() ? "" : " ", unit));
  return v;
}

std::string Doc::resolve(const std::string& relative) const {
  std::filesystem::path p(relative);
  if (p.is_absolute() || dir_.empty()) return p.string();
  return (std::filesystem::path(dir_) / p).lexically_normal().string();
}

std::string Doc::existing_file(const YAML::Node& node, const std::string& path) const {
  const std::string written = string(node, path);
  const std::string file = resolve(written);
  if (!std::filesystem::exists(file))
    fail(node, path,
         written == file ? fmt::format("no such file '{}'", written)
                         : fmt::format("no such file '{}' (paths are relative to the scenario "
                                       "file: looked for {})",
                                       written, file));
  if (std::filesystem::is_directory(file))
    fail(node, path, fmt::format("'{}' is a directory, not a file", written));
  return file;
}

}  // namespace kelvin::yamlutil
