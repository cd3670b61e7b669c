#include "engine/output.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "base/error.hpp"

namespace kelvin {

void write_file_atomic(const std::string& path, const std::string& contents) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    errno = 0;
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out)
      throw Error(fmt::format("{}: cannot write ({}: {})", path, tmp, std::strerror(errno)));
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.close();
    if (out.fail()) {
      const int err = errno;
      std::remove(tmp.c_str());
      throw Error(fmt::format("{}: write failed ({}: {})", path, tmp, std::strerror(err)));
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    std::remove(tmp.c_str());
    throw Error(fmt::format("{}: cannot replace ({})", path, std::strerror(err)));
  }
}

MarkerCsvWriter::MarkerCsvWriter(std::string path, std::vector<std::string> names)
    : path_(std::move(path)), names_(std::move(names)) {}

void MarkerCsvWriter::add_frame(double t, const Eigen::Matrix3Xd& positions) {
  if (positions.cols() != static_cast<Eigen::Index>(names_.size()))
    throw Error(fmt::format("{}: frame at t={} has {} marker positions, expected {}", path_, t,
                            positions.cols(), names_.size()));
  times_.push_back(t);
  rows_.push_back(positions);
}

void MarkerCsvWriter::flush() const {
  std::string s = "t";
  for (const auto& n : names_) s += fmt::format(",{0}_x,{0}_y,{0}_z", n);
  s += '\n';
  for (size_t f = 0; f < times_.size(); ++f) {
    s += fmt::format("{:.9g}", times_[f]);
    for (Eigen::Index i = 0; i < rows_[f].cols(); ++i)
      s += fmt::format(",{:.9g},{:.9g},{:.9g}", rows_[f](0, i), rows_[f](1, i), rows_[f](2, i));
    s += '\n';
  }
  write_file_atomic(path_, s);
}

VtuSeries::VtuSeries(std::string directory, std::string basename, const Mesh& mesh)
    : dir_(std::move(directory)), base_(std::move(basename)), mesh_(mesh) {
  std::error_code ec;
  if (!dir_.empty()) std::filesystem::create_directories(dir_, ec);
  if (ec) throw Error(fmt::format("{}: cannot create directory ({})", dir_, ec.message()));
}

namespace {

/// Collects VTK "appended raw" blocks: each array is a UInt64 byte count + bytes.
struct Appended {
  std::string bytes;
  template <class T>
  size_t add(const T* data, size_t count) {
    const size_t offset = bytes.size();
    const std::uint64_t size = count * sizeof(T);
    bytes.append(reinterpret_cast<const char*>(&size), sizeof size);
    bytes.append(reinterpret_cast<const char*>(data), size);
    return offset;
  }
};

}  // namespace

void VtuSeries::write_frame(
    double t, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
    const std::vector<std::pair<std::string, Eigen::VectorXd>>& cell_fields) {
  const int nn = mesh_.num_nodes(), ne = mesh_.num_tets();
  // The arrays are copied by byte count, so a size mismatch would read out of bounds.
  if (x.cols() != nn || v.cols() != nn)
    throw Error(fmt::format("{}/{}: frame at t={}: {} positions and {} velocities for {} nodes",
                            dir_, base_, t, x.cols(), v.cols(), nn));
  for (const auto& [name, field] : cell_fields)
    if (field.size() != ne)
      throw Error(fmt::format("{}/{}: cell field '{}' has {} values for {} tetrahedra", dir_, base_,
                              name, field.size(), ne));
  Appended data;
  std::string xml;
  auto array = [&](const char* type, const std::string& name, int comps, size_t offset) {
    xml += fmt::format(
        "        <DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"appended\" "
        "offset=\"{}\"/>\n",
        type, name, comps, offset);
  };
  const Eigen::Matrix3Xd disp = x - mesh_.nodes;
  xml += "      <PointData Vectors=\"displacement\">\n";
  array("Float64", "displacement", 3, data.add(disp.data(), 3 * nn));
  array("Float64", "velocity", 3, data.add(v.data(), 3 * nn));
  xml += "      </PointData>\n      <CellData>\n";
  std::vector<std::int32_t> region(ne, 0);
  for (int e = 0; e < ne && e < static_cast<int>(mesh_.region.size()); ++e)
    region[e] = mesh_.region[e];
  array("Int32", "region", 1, data.add(region.data(), ne));
  for (const auto& [name, field] : cell_fields)
    array("Float64", name, 1, data.add(field.data(), ne));
  xml += "      </CellData>\n      <Points>\n";
  array("Float64", "points", 3, data.add(x.data(), 3 * nn));
  xml += "      </Points>\n      <Cells>\n";
  std::vector<std::int64_t> conn(4 * static_cast<size_t>(ne)), offsets(ne);
  std::vector<std::uint8_t> types(ne, 10);  // VTK_TETRA
  for (int e = 0; e < ne; ++e) {
    for (int k = 0; k < 4; ++k) conn[4 * e + k] = mesh_.tets(k, e);
    offsets[e] = 4 * (e + 1);
  }
  array("Int64", "connectivity", 1, data.add(conn.data(), conn.size()));
  array("Int64", "offsets", 1, data.add(offsets.data(), offsets.size()));
  array("UInt8", "types", 1, data.add(types.data(), types.size()));
  xml += "      </Cells>\n";

  const std::string file = fmt::format("{}_{:05d}.vtu", base_, entries_.size());
  std::string doc = fmt::format(
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" "
      "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  <UnstructuredGrid>\n"
      "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n{}    </Piece>\n"
      "  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _",
      nn, ne, xml);
  doc += data.bytes;
  doc += "\n  </AppendedData>\n</VTKFile>\n";
  write_file_atomic((std::filesystem::path(dir_) / file).string(), doc);
  entries_.emplace_back(t, file);

  std::string pvd =
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n";
  for (const auto& [time, name] : entries_)
    pvd += fmt::format("    <DataSet timestep=\"{:.9g}\" part=\"0\" file=\"{}\"/>\n", time, name);
  pvd += "  </Collection>\n</VTKFile>\n";
  write_file_atomic((std::filesystem::path(dir_) / (base_ + ".pvd")).string(), pvd);
}

}  // namespace kelvin
