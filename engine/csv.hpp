#pragma once
// Readers for the CSV formats of DESIGN.md. Errors name the file and 1-based line.
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

namespace kelvin {

/// Content lines of a CSV file with their 1-based numbers: blank and '#' lines
/// dropped, CR of CRLF endings removed. Throws kelvin::Error when unreadable.
std::vector<std::pair<int, std::string>> read_csv_lines(const std::string& path);
/// Comma-separated cells, each trimmed of spaces and tabs.
std::vector<std::string> split_csv_line(const std::string& line);
/// The whole cell as a number (strtod); false for an empty or partly numeric cell.
bool parse_csv_number(const std::string& cell, double& value);

struct MarkerRest {
  std::vector<std::string> names;
  Eigen::Matrix3Xd positions;
};
/// `name,x,y,z` rows (a header line is allowed).
MarkerRest read_marker_rest(const std::string& path);

struct NodePositions {
  std::vector<int> nodes;  // 0-based mesh node ids, each once
  Eigen::Matrix3Xd positions;
};
/// `node,x,y,z` rows (a header line is allowed); `num_nodes` bounds the ids.
NodePositions read_node_positions(const std::string& path, int num_nodes);

struct MarkerTracks {
  std::vector<std::string> names;  // marker names from the header: <name>_x,_y,_z
  std::vector<double> times;       // strictly increasing
  Eigen::MatrixXd xyz;             // (3 × markers) × frames; NaN = occluded
};
/// Wide layout `t,a_x,a_y,a_z,b_x,...`; empty cells or NaN mean occluded.
MarkerTracks read_marker_tracks(const std::string& path);

struct ClampSamples {
  std::vector<double> t;
  std::vector<Eigen::Vector3d> translation;
  std::vector<Eigen::Vector4d> quaternion_wxyz;  // normalised on read
};
/// `t,tx,ty,tz,qw,qx,qy,qz` rows; at least 2 rows, strictly increasing t.
ClampSamples read_clamp_csv(const std::string& path);

}  // namespace kelvin
