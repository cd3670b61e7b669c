#pragma once
// Simulation outputs. Every file is written atomically (temp file + rename), so a
// killed run leaves either the previous or the new version, never a torn file.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "engine/mesh.hpp"

namespace kelvin {

/// Writes `contents` to `path` via `path.tmp.<pid>` + rename. Throws kelvin::Error.
void write_file_atomic(const std::string& path, const std::string& contents);

/// Marker trajectories in the wide CSV layout of DESIGN.md, kept in memory and
/// rewritten whole by flush().
class MarkerCsvWriter {
 public:
  MarkerCsvWriter(std::string path, std::vector<std::string> names);
  void add_frame(double t, const Eigen::Matrix3Xd& positions);
  void flush() const;
  int frames() const { return static_cast<int>(times_.size()); }

 private:
  std::string path_;
  std::vector<std::string> names_;
  std::vector<double> times_;
  std::vector<Eigen::Matrix3Xd> rows_;
};

/// ParaView series: one `<base>_NNNNN.vtu` per frame (appended raw binary,
/// UInt64 headers) and `<base>.pvd` rewritten after every frame.
class VtuSeries {
 public:
  VtuSeries(std::string directory, std::string basename, const Mesh& mesh);
  /// x: current positions (3 × nodes); point data displacement x − X and velocity;
  /// cell data: each named per-tet field.
  void write_frame(double t, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                   const std::vector<std::pair<std::string, Eigen::VectorXd>>& cell_fields);
  int frames() const { return static_cast<int>(entries_.size()); }

 private:
  std::string dir_, base_;
  const Mesh& mesh_;
  std::vector<std::pair<double, std::string>> entries_;
};

}  // namespace kelvin
