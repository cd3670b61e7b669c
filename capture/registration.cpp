#include "capture/registration.hpp"

#include <fmt/format.h>

#include <Eigen/SVD>
#include <cmath>

#include "base/error.hpp"

namespace kelvin {

double Registration::rms() const {
  if (residual.cols() == 0) return 0;
  return std::sqrt(residual.colwise().squaredNorm().mean());
}

Registration fit_registration(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to,
                              std::vector<std::string> names) {
  const long n = from.cols();
  if (n != to.cols()) throw Error("fit_registration: point sets of different sizes");
  if (n < 3)
    throw Error(
        fmt::format("a registration needs at least 3 markers with model positions (got {})", n));
  const Eigen::Vector3d a = from.rowwise().mean(), b = to.rowwise().mean();
  const Eigen::Matrix3Xd A = from.colwise() - a, B = to.colwise() - b;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(B * A.transpose(),
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  // Points on one line leave a rotation about it undetermined.
  const Eigen::Vector3d sv = svd.singularValues();
  if (!(sv[1] > 1e-10 * std::max(sv[0], 1e-300)))
    throw Error(
        fmt::format("the {} registration markers lie on one line: the rotation about it "
                    "is undetermined",
                    n));
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) D(2, 2) = -1;
  Registration r;
  r.R = svd.matrixU() * D * svd.matrixV().transpose();
  r.t = b - r.R * a;
  r.names = std::move(names);
  r.residual = to - ((r.R * from).colwise() + r.t);
  return r;
}

}  // namespace kelvin
