#include "fit/body_force_outputs.hpp"

#include <fmt/format.h>

#include <filesystem>
#include <iterator>

#include "engine/output.hpp"

namespace kelvin {

std::vector<std::string> write_body_force(const FemModel& model, const std::string& outdir,
                                          const std::string& base) {
  const BodyForceField& field = model.body_force();
  if (!field.active()) return {};
  const Mesh& mesh = model.mesh();
  const int ne = mesh.num_tets();
  std::filesystem::create_directories(outdir);
  std::string csv = "t,element,fx,fy,fz\n";
  VtuSeries vtu(outdir, base, mesh);
  for (int k = 0; k < field.knots(); ++k) {
    const double t = field.knot_time(k);
    std::vector<std::pair<std::string, Eigen::VectorXd>> cells;
    for (const char* name : {"force_x", "force_y", "force_z", "force_magnitude"})
      cells.emplace_back(name, Eigen::VectorXd(ne));
    for (int e = 0; e < ne; ++e) {
      Eigen::Vector3d f;
      for (int i = 0; i < 3; ++i) {
        f[i] = model.density()[e] * field.value(i, k, e);
        cells[i].second[e] = f[i];
      }
      cells[3].second[e] = f.norm();
      fmt::format_to(std::back_inserter(csv), "{:.9g},{},{:.9g},{:.9g},{:.9g}\n", t, e, f[0], f[1],
                     f[2]);
    }
    vtu.write_frame(t, mesh.nodes, Eigen::Matrix3Xd::Zero(3, mesh.num_nodes()), cells);
  }
  write_file_atomic((std::filesystem::path(outdir) / (base + ".csv")).string(), csv);
  return {base + ".csv", base + ".pvd"};
}

}  // namespace kelvin
