#include "diagnose/where.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <map>

#include "engine/markers.hpp"

namespace kelvin {
namespace {

constexpr int kWindows = 8;
const std::vector<double> kBandEdges = {0, 1, 3, 6, 12, 30};  // Hz, the last band to Nyquist

/// One coordinate's samples in time order: t, residual, observed.
struct Series {
  std::vector<double> t, r, obs;
};

/// Σ |Σₖ xₖ e^{−2πi f tₖ}|² over f = j/T in [f0, f1): power in a band of an
/// irregularly sampled (occluded) series.
double band_power(const Series& s, const std::vector<double>& x, double f0, double f1, double T) {
  double total = 0;
  for (int j = static_cast<int>(std::ceil(f0 * T)); j / T < f1; ++j) {
    if (j == 0) continue;  // the mean is no motion
    std::complex<double> sum = 0;
    const double w = 2 * M_PI * j / T;
    for (std::size_t k = 0; k < s.t.size(); ++k) sum += x[k] * std::polar(1.0, -w * s.t[k]);
    total += std::norm(sum);
  }
  return total;
}

}  // namespace

Eigen::Vector3d rest_position(const Mesh& mesh, const MarkerEmbedding& m) {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a) x += m.weights[a] * mesh.nodes.col(mesh.tets(a, m.tet));
  return x;
}

std::string region_of(double along) {
  return along < 1.0 / 3 ? "clamp zone" : along > 2.0 / 3 ? "free end" : "middle";
}

ResidualTables locate_residual(FitProblem& problem, const Eigen::VectorXd& r,
                               const std::vector<ResidualSample>& samples, const BodyAxis& axis,
                               double sigma) {
  ResidualTables out;
  Experiment& ex = problem.experiment(0);
  const MarkerObjective& objective = ex.objective();
  const Scenario& s = ex.scenario();
  const int nm = objective.num_markers();
  std::vector<std::array<Series, 3>> series(nm);
  double t_first = HUGE_VAL, t_last = -HUGE_VAL, dt = HUGE_VAL;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const ResidualSample& q = samples[k];
    if (q.experiment != 0) continue;
    const double res = r[static_cast<long>(k)] / q.sqrt_weight;
    const auto& names = s.markers.observed.names;
    const long column =
        std::find(names.begin(), names.end(), objective.names()[q.marker]) - names.begin();
    const auto& times = s.markers.observed.times;
    const long frame = std::lower_bound(times.begin(), times.end(), q.t) - times.begin();
    Series& z = series[q.marker][q.axis];
    if (!z.t.empty()) dt = std::min(dt, q.t - z.t.back());
    z.t.push_back(q.t);
    z.r.push_back(res);
    z.obs.push_back(s.markers.observed.xyz(3 * column + q.axis, frame));
    t_first = std::min(t_first, q.t);
    t_last = std::max(t_last, q.t);
  }
  if (!(t_last > t_first)) return out;

  // Per marker.
  for (int i = 0; i < nm; ++i) {
    MarkerResidual m;
    m.name = objective.names()[i];
    for (const auto& e : s.markers.embedded)
      if (e.name == m.name) m.along = axis.along(rest_position(s.mesh, e));
    m.region = region_of(m.along);
    double sum = 0, spread = -1;
    for (int c = 0; c < 3; ++c) {
      const Series& z = series[i][c];
      double sq = 0;
      for (double v : z.r) sq += v * v;
      m.rms[c] = z.r.empty() ? 0 : std::sqrt(sq / static_cast<double>(z.r.size()));
      sum += sq;
      m.samples += static_cast<int>(z.r.size());
      if (z.obs.size() > 1) {
        const Eigen::Map<const Eigen::VectorXd> o(z.obs.data(), static_cast<long>(z.obs.size()));
        const double var = (o.array() - o.mean()).square().mean();
        if (var > spread) {
          spread = var;
          m.main_axis = c;
        }
      }
    }
    m.rms_total = m.samples ? std::sqrt(sum / m.samples) : 0;
    m.excess = std::sqrt(std::max(0.0, m.rms_total * m.rms_total - sigma * sigma));
    // observed ≈ a·sim + b·d(sim)/dt (both demeaned) on the main axis: gain a, delay −b/a.
    const Series& z = series[i][m.main_axis];
    Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
    Eigen::Vector2d y = Eigen::Vector2d::Zero();
    double mean_obs = 0, mean_sim = 0;
    for (std::size_t k = 0; k < z.t.size(); ++k) {
      mean_obs += z.obs[k];
      mean_sim += z.obs[k] + z.r[k];
    }
    mean_obs /= std::max<std::size_t>(1, z.t.size());
    mean_sim /= std::max<std::size_t>(1, z.t.size());
    for (std::size_t k = 1; k + 1 < z.t.size(); ++k) {
      if (z.t[k + 1] - z.t[k - 1] > 2.02 * dt) continue;
      const double sim = z.obs[k] + z.r[k] - mean_sim;
      const double rate =
          (z.obs[k + 1] + z.r[k + 1] - z.obs[k - 1] - z.r[k - 1]) / (z.t[k + 1] - z.t[k - 1]);
      const Eigen::Vector2d phi(sim, rate);
      A += phi * phi.transpose();
      y += phi * (z.obs[k] - mean_obs);
    }
    if (A.determinant() > 0) {
      const Eigen::Vector2d ab = A.ldlt().solve(y);
      m.gain = ab[0];
      m.delay = ab[0] != 0 ? -ab[1] / ab[0] : 0;
    }
    out.markers.push_back(m);
  }

  // Per time window.
  for (int w = 0; w < kWindows; ++w) {
    WindowResidual win;
    win.t0 = t_first + (t_last - t_first) * w / kWindows;
    win.t1 = t_first + (t_last - t_first) * (w + 1) / kWindows;
    double sq = 0;
    int n = 0;
    for (const auto& m : series)
      for (const auto& z : m)
        for (std::size_t k = 0; k < z.t.size(); ++k)
          if (z.t[k] >= win.t0 && (z.t[k] < win.t1 || w == kWindows - 1)) {
            sq += z.r[k] * z.r[k];
            ++n;
          }
    win.rms = n ? std::sqrt(sq / n) : 0;
    out.windows.push_back(win);
  }

  // Per frequency band, summed over markers and axes.
  const double T = t_last - t_first + dt, nyquist = 0.5 / dt;
  std::vector<double> res_power(kBandEdges.size(), 0), sig_power(kBandEdges.size(), 0);
  for (const auto& m : series)
    for (const auto& z : m) {
      if (z.t.size() < 8) continue;
      const Eigen::Map<const Eigen::VectorXd> o(z.obs.data(), static_cast<long>(z.obs.size()));
      std::vector<double> demeaned(z.obs.size());
      for (std::size_t k = 0; k < z.obs.size(); ++k) demeaned[k] = z.obs[k] - o.mean();
      for (std::size_t b = 0; b < kBandEdges.size(); ++b) {
        const double f1 = b + 1 < kBandEdges.size() ? kBandEdges[b + 1] : nyquist;
        res_power[b] += band_power(z, z.r, kBandEdges[b], f1, T);
        sig_power[b] += band_power(z, demeaned, kBandEdges[b], f1, T);
      }
    }
  double res_total = 0, sig_total = 0;
  for (std::size_t b = 0; b < kBandEdges.size(); ++b) {
    res_total += res_power[b];
    sig_total += sig_power[b];
  }
  for (std::size_t b = 0; b < kBandEdges.size(); ++b) {
    BandResidual band;
    band.f0 = kBandEdges[b];
    band.f1 = b + 1 < kBandEdges.size() ? kBandEdges[b + 1] : nyquist;
    band.residual_fraction = res_total > 0 ? res_power[b] / res_total : 0;
    band.signal_fraction = sig_total > 0 ? sig_power[b] / sig_total : 0;
    out.bands.push_back(band);
  }

  // Per region.
  for (const char* name : {"clamp zone", "middle", "free end"}) {
    RegionResidual reg;
    reg.name = name;
    double sq = 0;
    int n = 0;
    for (const auto& m : out.markers)
      if (m.region == name) {
        reg.markers.push_back(m.name);
        sq += m.rms_total * m.rms_total * m.samples;
        n += m.samples;
      }
    reg.rms = n ? std::sqrt(sq / n) : 0;
    reg.excess = std::sqrt(std::max(0.0, reg.rms * reg.rms - sigma * sigma));
    out.regions.push_back(reg);
  }
  return out;
}

}  // namespace kelvin
