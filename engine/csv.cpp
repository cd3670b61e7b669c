#include "engine/csv.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <set>

#include "base/error.hpp"
#include "engine/input_size.hpp"

namespace kelvin {

/// Lines of a CSV file with their 1-based numbers; blank and '#' lines dropped,
/// CR of CRLF endings removed.
std::vector<std::pair<int, std::string>> read_csv_lines(const std::string& path) {
  check_data_file(path, "CSV file");
  std::ifstream in(path);
  if (!in) throw Error(fmt::format("{}: cannot open ({})", path, std::strerror(errno)));
  std::vector<std::pair<int, std::string>> lines;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (n == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);  // UTF-8 byte-order mark
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    lines.emplace_back(n, line);
  }
  return lines;
}

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> cells;
  size_t start = 0;
  for (;;) {
    const size_t comma = line.find(',', start);
    std::string cell =
        line.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    const auto a = cell.find_first_not_of(" \t"), b = cell.find_last_not_of(" \t");
    cells.push_back(a == std::string::npos ? "" : cell.substr(a, b - a + 1));
    if (comma == std::string::npos) return cells;
    start = comma + 1;
  }
}

bool parse_csv_number(const std::string& s, double& v) {
  if (s.empty()) return false;
  char* end = nullptr;
  // Underflow yields a usable denormal or zero; overflow gives ±inf, which the callers
  // refuse, so errno is not consulted.
  v = std::strtod(s.c_str(), &end);
  return end != s.c_str() && *end == '\0';
}

namespace {

/// A header is recognised only when none of its value cells is a number, so that a
/// first data row with one bad cell is reported instead of being skipped silently.
bool is_header_row(const std::vector<std::string>& cells, size_t from) {
  double v;
  for (size_t k = from; k < cells.size(); ++k)
    if (parse_csv_number(cells[k], v)) return false;
  return true;
}

double number(const std::string& path, int line, const std::string& cell, const char* what) {
  double v;
  if (!parse_csv_number(cell, v) || !std::isfinite(v))
    throw Error(fmt::format("{}:{}: {} '{}' is not a finite number", path, line, what, cell));
  return v;
}

}  // namespace

MarkerRest read_marker_rest(const std::string& path) {
  MarkerRest out;
  std::vector<Eigen::Vector3d> pos;
  std::set<std::string> seen;
  bool first = true;
  for (const auto& [n, line] : read_csv_lines(path)) {
    const auto cells = split_csv_line(line);
    if (cells.size() != 4)
      throw Error(
          fmt::format("{}:{}: expected 4 columns name,x,y,z, found {}", path, n, cells.size()));
    if (pos.empty() && first && is_header_row(cells, 1)) {
      first = false;
      continue;
    }
    first = false;
    if (cells[0].empty()) throw Error(fmt::format("{}:{}: empty marker name", path, n));
    if (!seen.insert(cells[0]).second)
      throw Error(fmt::format("{}:{}: marker '{}' appears twice", path, n, cells[0]));
    out.names.push_back(cells[0]);
    pos.emplace_back(number(path, n, cells[1], "x"), number(path, n, cells[2], "y"),
                     number(path, n, cells[3], "z"));
  }
  if (pos.empty()) throw Error(path + ": no marker rows");
  out.positions.resize(3, pos.size());
  for (size_t i = 0; i < pos.size(); ++i) out.positions.col(i) = pos[i];
  return out;
}

NodePositions read_node_positions(const std::string& path, int num_nodes) {
  NodePositions out;
  std::vector<Eigen::Vector3d> pos;
  std::map<int, int> line_of;
  bool first = true;
  for (const auto& [n, line] : read_csv_lines(path)) {
    const auto cells = split_csv_line(line);
    if (cells.size() != 4)
      throw Error(
          fmt::format("{}:{}: expected 4 columns node,x,y,z, found {}", path, n, cells.size()));
    if (first && is_header_row(cells, 0)) {
      first = false;
      continue;
    }
    first = false;
    char* end = nullptr;
    const long id = std::strtol(cells[0].c_str(), &end, 10);
    if (cells[0].empty() || *end != '\0' || id < 0 || id >= num_nodes)
      throw Error(
          fmt::format("{}:{}: node '{}' is not a node of the mesh (a whole number from 0 to {})",
                      path, n, cells[0], num_nodes - 1));
    if (const auto [it, fresh] = line_of.emplace(static_cast<int>(id), n); !fresh)
      throw Error(
          fmt::format("{}:{}: node {} appears twice (first on line {})", path, n, id, it->second));
    out.nodes.push_back(static_cast<int>(id));
    pos.emplace_back(number(path, n, cells[1], "x"), number(path, n, cells[2], "y"),
                     number(path, n, cells[3], "z"));
  }
  if (pos.empty()) throw Error(path + ": no node rows (expected node,x,y,z)");
  out.positions.resize(3, static_cast<Eigen::Index>(pos.size()));
  for (size_t i = 0; i < pos.size(); ++i) out.positions.col(static_cast<Eigen::Index>(i)) = pos[i];
  return out;
}

MarkerTracks read_marker_tracks(const std::string& path) {
  const auto lines = read_csv_lines(path);
  if (lines.empty()) throw Error(path + ": empty file (expected a header t,<name>_x,<name>_y,...)");
  const auto header = split_csv_line(lines[0].second);
  const int hn = lines[0].first;
  if (header[0] != "t" || (header.size() - 1) % 3 != 0)
    throw Error(fmt::format(
        "{}:{}: header must be t followed by <name>_x,<name>_y,<name>_z triplets", path, hn));
  if (header.size() < 4)
    throw Error(fmt::format("{}:{}: the header names no marker columns", path, hn));
  MarkerTracks out;
  std::set<std::string> seen;
  for (size_t k = 1; k < header.size(); k += 3) {
    const std::string& h = header[k];
    const std::string name = h.size() > 2 ? h.substr(0, h.size() - 2) : "";
    if (name.empty() || h.substr(h.size() - 2) != "_x" || header[k + 1] != name + "_y" ||
        header[k + 2] != name + "_z")
      throw Error(
          fmt::format("{}:{}: columns {}-{} must be <name>_x,<name>_y,<name>_z in this order", path,
                      hn, k + 1, k + 3));
    if (!seen.insert(name).second)
      throw Error(fmt::format("{}:{}: marker '{}' appears twice in the header", path, hn, name));
    out.names.push_back(name);
  }
  const int cols = static_cast<int>(header.size());
  std::vector<std::vector<double>> rows;
  for (size_t r = 1; r < lines.size(); ++r) {
    const auto& [n, line] = lines[r];
    const auto cells = split_csv_line(line);
    if (static_cast<int>(cells.size()) != cols)
      throw Error(fmt::format("{}:{}: {} columns, the header has {}", path, n, cells.size(), cols));
    std::vector<double> row(cols);
    row[0] = number(path, n, cells[0], "time");
    if (!out.times.empty() && !(row[0] > out.times.back()))
      throw Error(fmt::format("{}:{}: time {} does not increase (previous row: {})", path, n,
                              row[0], out.times.back()));
    for (int k = 1; k < cols; ++k) {
      double v;
      if (cells[k].empty())
        v = std::numeric_limits<double>::quiet_NaN();  // occluded
      else if (!parse_csv_number(cells[k], v) || std::isinf(v))
        throw Error(fmt::format("{}:{}: column {} ({}) '{}' is not a number", path, n, k + 1,
                                header[k], cells[k]));
      row[k] = v;
    }
    out.times.push_back(row[0]);
    rows.push_back(std::move(row));
  }
  if (rows.empty()) throw Error(path + ": no data rows after the header");
  out.xyz.resize(cols - 1, rows.size());
  for (size_t f = 0; f < rows.size(); ++f)
    for (int k = 1; k < cols; ++k) out.xyz(k - 1, f) = rows[f][k];
  return out;
}

ClampSamples read_clamp_csv(const std::string& path) {
  ClampSamples out;
  bool first = true;
  // Column of t, tx, ty, tz, qw, qx, qy, qz: kelvin's order unless a header names
  // another (scipy and ROS write quaternions x, y, z, w).
  static const char* names[8] = {"t", "tx", "ty", "tz", "qw", "qx", "qy", "qz"};
  int column[8] = {0, 1, 2, 3, 4, 5, 6, 7};
  for (const auto& [n, line] : read_csv_lines(path)) {
    const auto cells = split_csv_line(line);
    if (cells.size() != 8)
      throw Error(fmt::format("{}:{}: expected 8 columns t,tx,ty,tz,qw,qx,qy,qz, found {}", path, n,
                              cells.size()));
    if (first && is_header_row(cells, 0)) {
      first = false;
      std::set<std::string> given;
      for (int k = 0; k < 8; ++k) {
        const std::string& c = cells[k];
        const auto it = std::find(std::begin(names), std::end(names), c);
        if (it == std::end(names) || !given.insert(c).second)
          throw Error(fmt::format(
              "{}:{}: column {} of the header is '{}'; a clamp CSV's columns are t, tx, ty, tz, "
              "qw, qx, qy, qz, in any order, each once",
              path, n, k + 1, cells[k]));
        column[it - std::begin(names)] = k;
      }
      continue;
    }
    first = false;
    double v[8];
    for (int k = 0; k < 8; ++k) v[k] = number(path, n, cells[column[k]], names[k]);
    if (!out.t.empty() && !(v[0] > out.t.back()))
      throw Error(fmt::format("{}:{}: time {} does not increase (previous row: {})", path, n, v[0],
                              out.t.back()));
    Eigen::Vector4d q(v[4], v[5], v[6], v[7]);
    // A unit quaternion to the precision a capture system writes (6 decimals and more);
    // anything further off is a wrong column or a wrong convention.
    if (std::abs(q.norm() - 1) > 1e-3)
      throw Error(
          fmt::format("{}:{}: the quaternion (qw, qx, qy, qz) = ({}, {}, {}, {}) has norm "
                      "{:.6g}, not 1",
                      path, n, v[4], v[5], v[6], v[7], q.norm()));
    q.normalize();
    // q and −q are the same rotation; keep neighbours on one side so that the
    // spline through the components does not swing through zero.
    if (!out.quaternion_wxyz.empty() && q.dot(out.quaternion_wxyz.back()) < 0) q = -q;
    out.t.push_back(v[0]);
    out.translation.emplace_back(v[1], v[2], v[3]);
    out.quaternion_wxyz.push_back(q);
  }
  if (out.t.size() < 2) throw Error(path + ": a clamp trajectory needs at least 2 rows");
  return out;
}

}  // namespace kelvin
