#pragma once
// Helpers shared by the scenario loader: positioned error messages, key checking
// with did-you-mean suggestions, and typed reads of scalar and vector values.
// Every failure throws kelvin::Error "file:line:col: key.path: why".
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <string>
#include <vector>

namespace kelvin::yamlutil {

/// Edit distance (insertions, deletions, substitutions).
size_t levenshtein(const std::string& a, const std::string& b);

/// "did you mean 'x'?" when a candidate is within edit distance 2 or shares a
/// prefix with `word`; otherwise "allowed: a, b, c" (or `what`: a, b, c).
std::string suggestion(const std::string& word, const std::vector<std::string>& candidates,
                       const std::string& what = "allowed");

/// "a.b" from "a" and "b", and just "b" at the top level.
std::string join(const std::string& path, const std::string& key);
std::string index(const std::string& path, size_t i);

/// A parsed document and the file it came from, so that every read can point at
/// the offending text.
class Doc {
 public:
  /// Reads and parses `path`; syntax errors are reported with their position.
  explicit Doc(const std::string& path);

  const YAML::Node& root() const { return root_; }
  const std::string& file() const { return file_; }

  [[noreturn]] void fail(const YAML::Mark& at, const std::string& path,
                         const std::string& why) const;
  [[noreturn]] void fail(const YAML::Node& at, const std::string& path,
                         const std::string& why) const;

  /// Requires a mapping whose keys are all in `allowed` and appear once.
  void check_keys(const YAML::Node& map, const std::string& path,
                  const std::vector<std::string>& allowed) const;
  void require_map(const YAML::Node& node, const std::string& path) const;
  void require_sequence(const YAML::Node& node, const std::string& path) const;
  /// The value of `key` in `map`; a missing key is reported at the map.
  YAML::Node required(const YAML::Node& map, const std::string& path, const std::string& key) const;
  /// Position of `key` itself inside `map` (the value's position if not found).
  YAML::Mark key_mark(const YAML::Node& map, const std::string& key) const;

  double number(const YAML::Node& node, const std::string& path) const;
  long integer(const YAML::Node& node, const std::string& path) const;
  std::string string(const YAML::Node& node, const std::string& path) const;
  /// One of `choices`, with a suggestion when it is not.
  std::string choice(const YAML::Node& node, const std::string& path,
                     const std::vector<std::string>& choices) const;
  Eigen::Vector3d vec3(const YAML::Node& node, const std::string& path) const;

  /// Positive number (unit printed in the message when refused).
  double positive(const YAML::Node& node, const std::string& path, const std::string& unit) const;
  double non_negative(const YAML::Node& node, const std::string& path,
                      const std::string& unit) const;

  /// A path written in the document, made relative to the document's directory.
  std::string resolve(const std::string& relative) const;
  /// The file named by a scalar node, resolved and checked to exist.
  std::string existing_file(const YAML::Node& node, const std::string& path) const;

 private:
  std::string file_;
  std::string dir_;
  YAML::Node root_;
};

}  // namespace kelvin::yamlutil
