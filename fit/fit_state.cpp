#include "fit/fit_state.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "base/error.hpp"
#include "engine/csv.hpp"
#include "engine/output.hpp"

namespace kelvin {
namespace {

// 17 significant digits: the state and history must reproduce p exactly.
std::string exact(double v) {
  return fmt::format("{:.17g}", v);
}

}  // namespace

FitHistoryFile::FitHistoryFile(std::string path, const ParameterMap& map)
    : path_(std::move(path)), map_(map) {
  header_ =
      "evaluation,iteration,accepted,ok,objective,misfit,penalty,rms_mm,gradient_norm,seconds";
  if (map.size() <= kHistoryParameterColumns)
    for (int j = 0; j < map.size(); ++j) header_.append(",").append(map.label(j));
  header_ += ",error";
}

void FitHistoryFile::load_existing(int evaluations) {
  std::ifstream in(path_);
  if (!in) return;
  std::string line;
  if (!std::getline(in, line)) return;
  if (line != header_)
    throw Error(
        fmt::format("{}: line 1: the history belongs to a fit of other parameters "
                    "(header differs); start a fresh fit without --resume",
                    path_));
  int number = 1;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) continue;
    const auto cells = split_csv_line(line);
    if (cells.size() < 10)
      throw Error(fmt::format("{}: line {}: expected at least 10 columns", path_, number));
    FitRecord r;
    try {
      r.evaluation = std::stoi(cells[0]);
      r.iteration = std::stoi(cells[1]);
      r.accepted = cells[2] == "1";
      r.ok = cells[3] == "1";
      r.objective = std::stod(cells[4]);
      r.misfit = std::stod(cells[5]);
      r.penalty = std::stod(cells[6]);
      r.rms = std::stod(cells[7]) * 1e-3;
      r.gradient_norm = std::stod(cells[8]);
      r.seconds = std::stod(cells[9]);
    } catch (const std::exception&) {
      throw Error(fmt::format("{}: line {}: not a history row", path_, number));
    }
    if (r.evaluation > evaluations) continue;
    rows_.push_back(line);
    records_.push_back(r);
  }
}

void FitHistoryFile::append(const FitRecord& r) {
  std::string row =
      fmt::format("{},{},{},{},{},{},{},{},{},{:.3f}", r.evaluation, r.iteration,
                  r.accepted ? 1 : 0, r.ok ? 1 : 0, exact(r.objective), exact(r.misfit),
                  exact(r.penalty), exact(r.rms * 1e3), exact(r.gradient_norm), r.seconds);
  if (map_.size() <= kHistoryParameterColumns)
    for (int j = 0; j < map_.size(); ++j) row.append(",").append(exact(map_.value(r.p, j)));
  std::string error = r.error;
  for (char& ch : error)
    if (ch == ',' || ch == '\n') ch = ';';
  row.append(",").append(error);
  rows_.push_back(row);
  FitRecord kept = r;
  kept.p.resize(0);
  records_.push_back(kept);
  std::string text = header_ + "\n";
  for (const auto& line : rows_) text += line + "\n";
  write_file_atomic(path_, text);
}

void write_fit_state(const std::string& path, const FitState& s) {
  YAML::Emitter out;
  out << YAML::Comment("kelvin fit state: `kelvin fit --resume` continues from here");
  out << YAML::BeginMap;
  out << YAML::Key << "scenario" << YAML::Value << s.scenario;
  out << YAML::Key << "evaluations" << YAML::Value << s.evaluations;
  out << YAML::Key << "iterations" << YAML::Value << s.iterations;
  out << YAML::Key << "failures" << YAML::Value << s.failures;
  out << YAML::Key << "seconds" << YAML::Value << exact(s.seconds);
  out << YAML::Key << "tolerance_scale" << YAML::Value << exact(s.tolerance_scale);
  out << YAML::Key << "best_objective" << YAML::Value << exact(s.best_objective);
  out << YAML::Key << "best_rms" << YAML::Value << exact(s.best_rms);
  out << YAML::Key << "parameters" << YAML::Value << YAML::BeginSeq;
  for (size_t j = 0; j < s.labels.size(); ++j) {
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "label" << YAML::Value << s.labels[j];
    out << YAML::Key << "start" << YAML::Value << exact(s.start[j]);
    out << YAML::Key << "best" << YAML::Value << exact(s.best[j]);
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  write_file_atomic(path, std::string(out.c_str()) + "\n");
}

FitState read_fit_state(const std::string& path) {
  if (!std::filesystem::exists(path))
    throw Error(fmt::format("{}: no saved fit state to resume from (run without --resume)", path));
  FitState s;
  try {
    const YAML::Node root = YAML::LoadFile(path);
    s.scenario = root["scenario"].as<std::string>();
    s.evaluations = root["evaluations"].as<int>();
    s.iterations = root["iterations"].as<int>();
    s.failures = root["failures"].as<int>();
    s.seconds = root["seconds"].as<double>();
    // Absent in states saved before the loop could tighten the tolerances.
    if (root["tolerance_scale"]) s.tolerance_scale = root["tolerance_scale"].as<double>();
    s.best_objective = root["best_objective"].as<double>();
    s.best_rms = root["best_rms"].as<double>();
    const YAML::Node params = root["parameters"];
    const auto n = static_cast<long>(params.size());
    s.start.resize(n);
    s.best.resize(n);
    for (long j = 0; j < n; ++j) {
      s.labels.push_back(params[j]["label"].as<std::string>());
      s.start[j] = params[j]["start"].as<double>();
      s.best[j] = params[j]["best"].as<double>();
    }
  } catch (const YAML::Exception& e) {
    // A missing key has no position of its own (line 0): say so instead.
    if (e.mark.line < 0)
      throw Error(
          fmt::format("{}: malformed fit state (truncated, or a key missing): {}", path, e.msg));
    throw Error(fmt::format("{}: line {}: malformed fit state: {}", path, e.mark.line + 1, e.msg));
  }
  if (static_cast<long>(s.labels.size()) != static_cast<long>(s.best.size()) || s.best.size() == 0)
    throw Error(fmt::format("{}: malformed fit state: no parameters", path));
  return s;
}

}  // namespace kelvin
