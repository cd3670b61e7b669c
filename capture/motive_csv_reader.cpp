#include "capture/motive_csv_reader.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <map>

#include "base/error.hpp"

namespace kelvin {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string cell(const std::vector<std::string>& row, size_t k) {
  return k < row.size() ? row[k] : std::string();
}

double metres_per(const std::string& unit, const std::string& where) {
  if (unit.empty() || unit == "Meters") return 1;
  if (unit == "Millimeters") return 1e-3;
  if (unit == "Centimeters") return 1e-2;
  throw Error(
      fmt::format("{}: Length Units '{}' (known: Meters, Centimeters, Millimeters)", where, unit));
}

}  // namespace

Capture read_motive_csv(const std::string& path) {
  const auto lines = read_csv_lines(path);
  std::vector<std::pair<int, std::vector<std::string>>> rows;
  for (const auto& [line, text] : lines) rows.push_back({line, split_csv_line(text)});
  if (rows.empty() || cell(rows[0].second, 0) != "Format Version")
    throw Error(fmt::format(
        "{}:1: not a Motive CSV export (the first cell is not 'Format Version')", path));
  // Metadata: alternating key, value cells.
  std::map<std::string, std::string> meta;
  for (size_t k = 0; k + 1 < rows[0].second.size(); k += 2)
    meta[rows[0].second[k]] = rows[0].second[k + 1];
  const int meta_line = rows[0].first;
  const double unit = metres_per(meta["Length Units"], fmt::format("{}:{}", path, meta_line));
  if (meta.count("Rotation Type") && meta["Rotation Type"] != "Quaternion")
    throw Error(
        fmt::format("{}:{}: Rotation Type '{}': export rigid bodies with quaternions "
                    "(Motive's export option 'Rotation Type: Quaternion')",
                    path, meta_line, meta["Rotation Type"]));

  // The header rows are found by their label cells: Type, Name (column 1), and the
  // axis row starting with Frame.
  int type_row = -1, name_row = -1, axis_row = -1;
  for (int r = 1; r < static_cast<int>(rows.size()) && axis_row < 0; ++r) {
    const auto& row = rows[r].second;
    if (cell(row, 1) == "Type") type_row = r;
    if (cell(row, 1) == "Name") name_row = r;
    if (cell(row, 0) == "Frame") axis_row = r;
  }
  if (type_row < 0 || name_row < 0 || axis_row < 1)
    throw Error(
        fmt::format("{}: no Type, Name and Frame header rows (a Motive export has them "
                    "in rows 3, 4 and 7)",
                    path));
  const auto& types = rows[type_row].second;
  const auto& names = rows[name_row].second;
  const auto& properties = rows[axis_row - 1].second;
  const auto& axes = rows[axis_row].second;

  // Columns of each marker's position and each rigid body's pose.
  struct Columns {
    int x = -1, y = -1, z = -1, qx = -1, qy = -1, qz = -1, qw = -1;
  };
  std::vector<std::string> marker_names, body_names;
  std::map<std::string, Columns> marker_cols, body_cols;
  for (size_t k = 2; k < axes.size(); ++k) {
    const std::string type = cell(types, k), name = cell(names, k), prop = cell(properties, k);
    const std::string axis = axes[k];
    const bool marker = type == "Marker" || type == "Rigid Body Marker";
    const bool body = type == "Rigid Body" || type == "Bone";
    if (!marker && !body) continue;
    auto& cols = marker ? marker_cols : body_cols;
    auto& order = marker ? marker_names : body_names;
    if (!cols.count(name)) order.push_back(name);
    Columns& c = cols[name];
    if (prop == "Position") {
      if (axis == "X") c.x = static_cast<int>(k);
      if (axis == "Y") c.y = static_cast<int>(k);
      if (axis == "Z") c.z = static_cast<int>(k);
    } else if (prop == "Rotation") {
      if (axis == "X") c.qx = static_cast<int>(k);
      if (axis == "Y") c.qy = static_cast<int>(k);
      if (axis == "Z") c.qz = static_cast<int>(k);
      if (axis == "W") c.qw = static_cast<int>(k);
    }
  }

  Capture c;
  c.format = "Motive CSV " + meta["Format Version"];
  c.units = meta["Length Units"].empty() ? "Meters" : meta["Length Units"];
  for (const auto& n : marker_names)
    if (marker_cols[n].x >= 0 && marker_cols[n].y >= 0 && marker_cols[n].z >= 0)
      c.markers.names.push_back(track_name(n));
  const int nm = static_cast<int>(c.markers.names.size());
  const int frames = static_cast<int>(rows.size()) - axis_row - 1;
  if (frames < 1) throw Error(fmt::format("{}: no frames after the header", path));
  c.markers.xyz.setConstant(3 * nm, frames, kNaN);
  for (const auto& n : body_names) {
    const Columns& b = body_cols[n];
    if (b.x < 0 || b.qw < 0) continue;
    c.bodies.push_back({track_name(n), Eigen::MatrixXd::Constant(7, frames, kNaN)});
  }

  std::vector<Columns> mcols;
  for (const auto& n : marker_names)
    if (marker_cols[n].x >= 0 && marker_cols[n].y >= 0 && marker_cols[n].z >= 0)
      mcols.push_back(marker_cols[n]);
  std::vector<Columns> bcols;
  for (const auto& n : body_names)
    if (body_cols[n].x >= 0 && body_cols[n].qw >= 0) bcols.push_back(body_cols[n]);

  double t_first = 0;
  for (int k = 0; k < frames; ++k) {
    // Named copies: clang (before 16) refuses a lambda that captures structured bindings.
    const int line = rows[axis_row + 1 + k].first;
    const auto& row = rows[axis_row + 1 + k].second;
    const auto number = [&](int col, bool required) {
      double v = kNaN;
      const std::string s = cell(row, static_cast<size_t>(col));
      if (s.empty() && !required) return kNaN;
      if (!parse_csv_number(s, v) || !std::isfinite(v))
        throw Error(fmt::format("{}:{}: column {} ('{}'): '{}' is not a number", path, line,
                                col + 1, cell(axes, static_cast<size_t>(col)), s));
      return v;
    };
    const double t = number(1, true);
    if (k == 0) t_first = t;
    if (k > 0 && !(t - t_first > c.markers.times.back()))
      throw Error(fmt::format("{}:{}: time {:g} s does not increase", path, line, t));
    c.markers.times.push_back(t - t_first);
    for (int i = 0; i < nm; ++i) {
      const Columns& m = mcols[i];
      const double x = number(m.x, false), y = number(m.y, false), z = number(m.z, false);
      if (std::isnan(x) || std::isnan(y) || std::isnan(z)) continue;
      c.markers.xyz.col(k).segment<3>(3 * i) = Eigen::Vector3d(x, y, z) * unit;
    }
    for (size_t b = 0; b < bcols.size(); ++b) {
      const Columns& m = bcols[b];
      Eigen::Matrix<double, 7, 1> pose;
      pose << number(m.x, false) * unit, number(m.y, false) * unit, number(m.z, false) * unit,
          number(m.qw, false), number(m.qx, false), number(m.qy, false), number(m.qz, false);
      if (!pose.hasNaN()) c.bodies[b].pose.col(k) = pose;
    }
  }
  double rate = 0;
  if (!parse_csv_number(meta["Export Frame Rate"], rate) || !(rate > 0))
    rate = frames > 1 ? (frames - 1) / c.markers.times.back() : 0;
  c.rate = rate;
  return c;
}

}  // namespace kelvin
