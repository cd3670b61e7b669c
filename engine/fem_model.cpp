#include "engine/fem_model.hpp"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <exception>
#include <limits>

#include "base/error.hpp"
#include "engine/threads.hpp"

namespace kelvin {
namespace {

/// Below this many elements or entries a loop runs on one thread: the fork and
/// join of a parallel region (a few µs) would cost more than the work.
constexpr int kParallelMin = 256;

/// body(i) for i < count, split over the threads in fixed chunks.
template <class Body>
void parallel_for(int count, Body body) {
#pragma omp parallel for schedule(static) if (count >= kParallelMin)
  for (int i = 0; i < count; ++i) body(i);
}

/// The clamps' poses at one time, without allocating for up to four clamps (the
/// residual needs them at every evaluation).
class PosesAt {
 public:
  /// Ramped clamps (a probe pressed to a depth) at `ramp` of their translation.
  PosesAt(const std::vector<ClampBinding>& clamps, double t, double ramp = 1.0) {
    for (size_t c = 0; c < clamps.size(); ++c) {
      RigidPose pose = clamps[c].motion->at(t);
      if (clamps[c].ramped) {
        pose.d *= ramp;
        pose.ddot *= ramp;
        pose.dddot *= ramp;
      }
      if (c < kInline)
        inline_[c] = pose;
      else
        more_.push_back(pose);
    }
  }
  const RigidPose& operator[](int c) const {
    return c < static_cast<int>(kInline) ? inline_[c] : more_[c - kInline];
  }

 private:
  static constexpr size_t kInline = 4;
  RigidPose inline_[kInline];
  std::vector<RigidPose> more_;
};

}  // namespace

Eigen::SparseMatrix<double> to_sparse_matrix(const SparsePattern& pattern,
                                             const std::vector<double>& values) {
  Eigen::SparseMatrix<double> A(pattern.n, pattern.n);
  A.reserve(pattern.nnz());
  std::copy(pattern.colptr.begin(), pattern.colptr.end(), A.outerIndexPtr());
  std::copy(pattern.rowind.begin(), pattern.rowind.end(), A.innerIndexPtr());
  std::copy(values.begin(), values.end(), A.valuePtr());
  A.resizeNonZeros(pattern.nnz());
  return A;
}

FemModel::FemModel(const Mesh& mesh, std::vector<MaterialTerm> terms, Eigen::VectorXd density,
                   Eigen::Vector3d gravity, std::vector<ClampBinding> clamps, bool lumped_mass,
                   const std::vector<NodeLoad>& loads)
    : mesh_(mesh),
      terms_(std::move(terms)),
      density_(std::move(density)),
      gravity_(gravity),
      clamps_(std::move(clamps)),
      lumped_(lumped_mass) {
  const int nn = mesh.num_nodes(), ne = mesh.num_tets();
  if (density_.size() != ne) throw Error("density field size does not match the mesh");
  for (const auto& term : terms_)
    if (term.q.cols() != ne || term.q.rows() != static_cast<int>(term.model->params().size()))
      throw Error(
          fmt::format("parameter field of material '{}' has the wrong shape", term.model->name()));
  for (const auto& term : terms_)
    if (term.model->state_size() > 0 &&
        (term.state.rows() != term.model->state_size() || term.state.cols() != ne))
      throw Error(
          fmt::format("state field of material '{}' has the wrong shape", term.model->name()));
  elements_.reserve(ne);
  for (int e = 0; e < ne; ++e) elements_.push_back(make_tet_element(mesh, e));

  std::vector<int> holder(nn, -1);
  for (int c = 0; c < static_cast<int>(clamps_.size()); ++c)
    for (int node : clamps_[c].nodes) {
      if (holder[node] >= 0)
        throw Error(fmt::format("node {} belongs to clamps '{}' and '{}'", node,
                                clamps_[holder[node]].name, clamps_[c].name));
      holder[node] = c;
    }
  // A compliant clamp's nodes stay unknowns; only rigid clamps eliminate theirs.
  clamp_of_node_.assign(nn, -1);
  for (int a = 0; a < nn; ++a)
    if (holder[a] >= 0 && !clamps_[holder[a]].compliant()) clamp_of_node_[a] = holder[a];
  dof_.assign(3 * nn, -1);
  for (int a = 0; a < nn; ++a)
    if (clamp_of_node_[a] < 0)
      for (int i = 0; i < 3; ++i) dof_[3 * a + i] = n_++;
  attached_mass_.setZero(nn);
  load_force_.setZero(3, nn);
  for (const auto& load : loads) {
    std::vector<int> free;
    for (int node : load.nodes) {
      if (node < 0 || node >= nn)
        throw Error(fmt::format("load '{}' names node {}, outside the mesh", load.name, node));
      if (clamp_of_node_[node] < 0) free.push_back(node);
    }
    if (free.empty())
      throw Error(
          fmt::format("load '{}' has no free node: a clamp holds all of its nodes", load.name));
    for (int node : free) {
      attached_mass_[node] += load.mass / static_cast<double>(free.size());
      load_force_.col(node) += load.force / static_cast<double>(free.size());
    }
  }
  build_pattern();
  for (int c = 0; c < static_cast<int>(clamps_.size()); ++c) {
    if (!clamps_[c].compliant()) continue;
    const auto faces = kelvin::clamp_faces(mesh_, clamps_[c].nodes, c);
    if (faces.empty())
      throw Error(fmt::format(
          "clamp '{}' is compliant, and its nodes cover no boundary face for its springs to act "
          "on",
          clamps_[c].name));
    clamp_faces_.insert(clamp_faces_.end(), faces.begin(), faces.end());
  }
  for (const auto& f : clamp_faces_)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int i = 0; i < 3; ++i)
          clamp_face_entries_.push_back(pattern_.find(dof(f.nodes[a], i), dof(f.nodes[b], i)));
  build_mass();
  update_rest_tangents();
  number_internal_variables();
}

void FemModel::scatter_element_matrix(int e, const Eigen::Matrix<double, 12, 12>& A,
                                      double* values) const {
  const int* sc = &scatter_[static_cast<size_t>(e) * 144];
  for (int k = 0; k < 144; ++k)
    if (sc[k] >= 0) values[sc[k]] += A(k % 12, k / 12);
}

void FemModel::set_clamp_compliance(int clamp, double compliance) {
  if (!clamps_.at(clamp).compliant() || !(compliance > 0))
    throw Error(
        fmt::format("clamp '{}': a compliance can be set only on a compliant clamp, and "
                    "only to a positive value (got {})",
                    clamps_.at(clamp).name, compliance));
  clamps_[clamp].compliance = compliance;
}

void FemModel::add_clamp_springs(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                 const AssemblyRequest& req, AssemblyOutput& out) const {
  if (req.force)
    for (const auto& f : clamp_faces_) {
      const ClampBinding& c = clamps_[f.clamp];
      for (int a = 0; a < 3; ++a) {
        const Eigen::Vector3d sum = face_product(f, a, [&](int b) -> Eigen::Vector3d {
          return (x.col(f.nodes[b]) + c.damping_time * v.col(f.nodes[b])) / c.compliance;
        });
        for (int i = 0; i < 3; ++i) out.force[dof(f.nodes[a], i)] += sum[i];
      }
    }
  add_clamp_spring_matrices(req.stiffness ? &out.K : nullptr, req.damping ? &out.D : nullptr);
}

void FemModel::add_clamp_spring_matrices(std::vector<double>* K, std::vector<double>* D) const {
  const int* entry = clamp_face_entries_.data();
  for (const auto& f : clamp_faces_) {
    const ClampBinding& c = clamps_[f.clamp];
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int i = 0; i < 3; ++i, ++entry) {
          if (K) (*K)[*entry] += face_weight(f, a, b) / c.compliance;
          if (D) (*D)[*entry] += face_weight(f, a, b) * c.damping_time / c.compliance;
        }
  }
}

double FemModel::clamp_spring_energy(double t, const Eigen::Matrix3Xd& x) const {
  if (clamp_faces_.empty()) return 0;
  const PosesAt poses(clamps_, t);
  double energy = 0;
  for (const auto& f : clamp_faces_) {
    Eigen::Vector3d gap[3];
    for (int a = 0; a < 3; ++a)
      gap[a] = x.col(f.nodes[a]) - poses[f.clamp].position(mesh_.nodes.col(f.nodes[a]));
    for (int a = 0; a < 3; ++a)
      energy += 0.5 * gap[a].dot(face_product(f, a, [&](int b) { return gap[b]; })) /
                clamps_[f.clamp].compliance;
  }
  return energy;
}

void FemModel::body_force_load(double t, Eigen::VectorXd& out) const {
  out.setZero(n_);
  if (!body_force_.active()) return;
  for (int e = 0; e < mesh_.num_tets(); ++e) {
    const Eigen::Vector3d f = density_[e] * elements_[e].volume / 4 * body_force_.at(e, t);
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i)
        if (const int d = dof(elements_[e].nodes[a], i); d >= 0) out[d] += f[i];
  }
}

void FemModel::clamp_pull(double t, bool with_velocity, Eigen::VectorXd& out) const {
  out.setZero(n_);
  if (clamp_faces_.empty()) return;
  const PosesAt poses(clamps_, t);
  for (const auto& f : clamp_faces_) {
    const ClampBinding& c = clamps_[f.clamp];
    Eigen::Vector3d target[3];
    for (int b = 0; b < 3; ++b) {
      const Eigen::Vector3d X = mesh_.nodes.col(f.nodes[b]);
      target[b] = poses[f.clamp].position(X);
      if (with_velocity) target[b] += c.damping_time * poses[f.clamp].velocity(X);
      target[b] /= c.compliance;
    }
    for (int a = 0; a < 3; ++a) {
      const Eigen::Vector3d sum = face_product(f, a, [&](int b) { return target[b]; });
      for (int i = 0; i < 3; ++i) out[dof(f.nodes[a], i)] += sum[i];
    }
  }
}

std::pair<int, double> FemModel::most_compressed_element(const Eigen::Matrix3Xd& x) const {
  std::pair<int, double> worst{-1, std::numeric_limits<double>::infinity()};
  Eigen::Matrix<double, 3, 4> xe;
  for (int e = 0; e < mesh_.num_tets(); ++e) {
    for (int a = 0; a < 4; ++a) xe.col(a) = x.col(elements_[e].nodes[a]);
    const double det = (xe * elements_[e].G.transpose()).determinant();
    if (det < worst.second) worst = {e, det};
  }
  return worst;
}

void FemModel::update_rest_tangents() {
  const bool needed = std::any_of(terms_.begin(), terms_.end(), [](const MaterialTerm& t) {
    return t.model->needs_rest_tangent();
  });
  if (!needed) return;
  const int ne = mesh_.num_tets();
  rest_tangent_.assign(ne, Mat9::Zero());
  MaterialPoint mp;
  MaterialResponse resp;
  for (int e = 0; e < ne; ++e)
    for (const auto& term : terms_) {
      // A branch with internal variables carries no stress at rest: it has no C₀.
      if (term.model->is_viscous() || term.model->internal_size() > 0) continue;
      mp.q = term.q.col(e).data();
      mp.state = term.state.size() ? term.state.col(e).data() : nullptr;
      mp.element = e;
      if (!term.model->evaluate(mp, kTangent, resp))
        throw Error(fmt::format("material '{}' cannot evaluate its rest tangent in element {}",
                                term.model->name(), e));
      rest_tangent_[e] += resp.dPdF;
    }
}

void FemModel::build_pattern() {
  // Node adjacency through elements, expanded to 3×3 dof blocks.
  const int ne = mesh_.num_tets();
  std::vector<std::vector<int>> cols(n_);
  for (const auto& el : elements_)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int i = 0; i < 3; ++i)
          for (int k = 0; k < 3; ++k) {
            const int r = dof(el.nodes[a], i), c = dof(el.nodes[b], k);
            if (r >= 0 && c >= 0) cols[c].push_back(r);
          }
  pattern_.n = n_;
  pattern_.colptr.assign(n_ + 1, 0);
  for (int c = 0; c < n_; ++c) {
    auto& col = cols[c];
    col.push_back(c);  // the diagonal is always present (lumped mass lives there)
    std::sort(col.begin(), col.end());
    col.erase(std::unique(col.begin(), col.end()), col.end());
    pattern_.colptr[c + 1] = pattern_.colptr[c] + static_cast<int>(col.size());
  }
  pattern_.rowind.reserve(pattern_.colptr[n_]);
  for (auto& col : cols) pattern_.rowind.insert(pattern_.rowind.end(), col.begin(), col.end());

  scatter_.assign(static_cast<size_t>(ne) * 144, -1);
  for (int e = 0; e < ne; ++e)
    for (int b = 0; b < 12; ++b) {
      const int c = dof(elements_[e].nodes[b / 3], b % 3);
      if (c < 0) continue;
      for (int a = 0; a < 12; ++a) {
        const int r = dof(elements_[e].nodes[a / 3], a % 3);
        if (r >= 0) scatter_[static_cast<size_t>(e) * 144 + 12 * b + a] = pattern_.find(r, c);
      }
    }
  build_gather_plan();
}

void FemModel::build_gather_plan() {
  const int ne = mesh_.num_tets();
  // Counting sort by target, visiting elements in ascending order, so each target's
  // sources are in ascending element order.
  auto plan = [ne](int targets, int per_element, auto target_of, std::vector<int>& ptr,
                   std::vector<int>& src) {
    ptr.assign(targets + 1, 0);
    for (int e = 0; e < ne; ++e)
      for (int k = 0; k < per_element; ++k)
        if (const int t = target_of(e, k); t >= 0) ++ptr[t + 1];
    for (int t = 0; t < targets; ++t) ptr[t + 1] += ptr[t];
    src.resize(ptr[targets]);
    std::vector<int> next(ptr.begin(), ptr.end() - 1);
    for (int e = 0; e < ne; ++e)
      for (int k = 0; k < per_element; ++k)
        if (const int t = target_of(e, k); t >= 0) src[next[t]++] = per_element * e + k;
  };
  plan(
      n_, 12, [this](int e, int k) { return dof(elements_[e].nodes[k / 3], k % 3); }, dof_ptr_,
      dof_src_);
  plan(
      pattern_.nnz(), 144,
      [this](int e, int k) { return scatter_[144 * static_cast<size_t>(e) + k]; }, entry_ptr_,
      entry_src_);
}

void FemModel::gather(const std::vector<int>& ptr, const std::vector<int>& src, const double* slots,
                      double* out) const {
  parallel_for(static_cast<int>(ptr.size()) - 1, [&](int t) {
    double sum = 0;
    for (int k = ptr[t]; k < ptr[t + 1]; ++k) sum += slots[src[k]];
    out[t] = sum;
  });
}

template <class Body>
std::pair<int, double> FemModel::for_each_element(const Eigen::Matrix3Xd& x,
                                                  const Eigen::Matrix3Xd& v, const double* z,
                                                  unsigned request,
                                                  std::vector<ElementResponse>& scratch,
                                                  Body body) const {
  const int ne = mesh_.num_tets();
  if (static_cast<int>(scratch.size()) < thread_count()) scratch.resize(thread_count());
  int failed = ne, thrown_at = ne;
  std::exception_ptr thrown;  // exceptions must not leave a parallel region
#pragma omp parallel for schedule(static) reduction(min : failed) if (ne >= kParallelMin)
  for (int e = 0; e < ne; ++e) {
    ElementResponse& er = scratch[thread_index()];
    try {
      if (evaluate_element(e, x, v, request, er, z))
        body(e, er);
      else
        failed = std::min(failed, e);
    } catch (...) {
#pragma omp critical(kelvin_element_exception)
      if (e < thrown_at) {
        thrown_at = e;
        thrown = std::current_exception();
      }
    }
  }
  if (thrown && thrown_at <= failed) std::rethrow_exception(thrown);
  if (failed == ne) return {-1, 0.0};
  ElementResponse& er = scratch[0];
  evaluate_element(failed, x, v, request, er, z);  // again, for its det F
  return {failed, er.det_F};
}

void FemModel::build_mass() {
  // Consistent mass of a linear tet: ρV/20 (1 + δ_ab) per node pair and direction;
  // its row sums are the lumped masses ρV/4.
  const int nn = mesh_.num_nodes();
  node_mass_.setZero(nn);
  clamp_coupled_elements_.clear();
  mass_.assign(pattern_.nnz(), 0.0);
  for (int e = 0; e < mesh_.num_tets(); ++e) {
    const auto& el = elements_[e];
    const double m = density_[e] * el.volume;
    bool has_free = false, has_clamped = false;
    for (int a = 0; a < 4; ++a) {
      node_mass_[el.nodes[a]] += m / 4;
      (clamp_of_node_[el.nodes[a]] < 0 ? has_free : has_clamped) = true;
    }
    if (has_free && has_clamped) clamp_coupled_elements_.push_back(e);
    const Eigen::Matrix<double, 12, 12> Me = element_mass(e);
    const int* sc = &scatter_[static_cast<size_t>(e) * 144];
    for (int k = 0; k < 144; ++k)
      if (sc[k] >= 0 && Me(k % 12, k / 12) != 0) mass_[sc[k]] += Me(k % 12, k / 12);
  }
  if (lumped_) clamp_coupled_elements_.clear();
  // Attached masses are point masses: diagonal entries, lumped or consistent.
  node_mass_ += attached_mass_;
  for (int a = 0; a < nn; ++a)
    for (int i = 0; i < 3; ++i) {
      const int d = dof(a, i);
      if (d >= 0) mass_[pattern_.find(d, d)] += attached_mass_[a];
    }
  mass_diagonal_.resize(n_);
  for (int d = 0; d < n_; ++d) mass_diagonal_[d] = mass_[pattern_.find(d, d)];
  f_external_.setZero(n_);
  for (int a = 0; a < nn; ++a)
    for (int i = 0; i < 3; ++i)
      if (dof(a, i) >= 0) f_external_[dof(a, i)] = node_mass_[a] * gravity_[i] + load_force_(i, a);
}

void FemModel::set_density(Eigen::VectorXd density) {
  if (density.size() != mesh_.num_tets()) throw Error("density field size does not match the mesh");
  density_ = std::move(density);
  build_mass();
}

Eigen::Matrix<double, 12, 12> FemModel::element_mass(int e) const {
  const double m = density_[e] * elements_[e].volume;
  Eigen::Matrix<double, 12, 12> M = Eigen::Matrix<double, 12, 12>::Zero();
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) {
      if (lumped_ && a != b) continue;
      const double mab = lumped_ ? m / 4 : m / 20 * (a == b ? 2 : 1);
      for (int i = 0; i < 3; ++i) M(3 * a + i, 3 * b + i) = mab;
    }
  return M;
}

Eigen::Matrix<double, 3, 4> FemModel::element_mass_times(
    int e, const Eigen::Matrix<double, 3, 4>& u) const {
  // Consistent: M_ab = m/20 (1 + δ_ab) I₃, so (M u)_a = m/20 (u_a + Σ_b u_b); lumped m/4 u_a.
  const double m = density_[e] * elements_[e].volume;
  if (lumped_) return (m / 4) * u;
  return (m / 20) * (u.colwise() + u.rowwise().sum());
}

void FemModel::expand(double t, const double* x_free, const double* v_free, Eigen::Matrix3Xd& x,
                      Eigen::Matrix3Xd& v, double ramp) const {
  const int nn = mesh_.num_nodes();
  x.resize(3, nn);
  v.resize(3, nn);
  const PosesAt poses(clamps_, t, ramp);
  parallel_for(nn, [&](int a) {
    const int c = clamp_of_node_[a];
    if (c >= 0) {
      const Eigen::Vector3d X = mesh_.nodes.col(a);
      x.col(a) = poses[c].position(X);
      v.col(a) = poses[c].velocity(X);
    } else {
      for (int i = 0; i < 3; ++i) {
        x(i, a) = x_free[dof(a, i)];
        v(i, a) = v_free ? v_free[dof(a, i)] : 0.0;
      }
    }
  });
}

void FemModel::expand_acceleration(double t, const double* a_free, Eigen::Matrix3Xd& a) const {
  const int nn = mesh_.num_nodes();
  a.resize(3, nn);
  const PosesAt poses(clamps_, t);
  for (int node = 0; node < nn; ++node) {
    const int c = clamp_of_node_[node];
    if (c >= 0)
      a.col(node) = poses[c].acceleration(mesh_.nodes.col(node));
    else
      for (int i = 0; i < 3; ++i) a(i, node) = a_free[dof(node, i)];
  }
}

void FemModel::restrict(const Eigen::Matrix3Xd& full, double* free) const {
  for (int a = 0; a < mesh_.num_nodes(); ++a)
    for (int i = 0; i < 3; ++i)
      if (dof(a, i) >= 0) free[dof(a, i)] = full(i, a);
}

void FemModel::clamp_inertia(double t, Eigen::VectorXd& out) const {
  out.setZero(n_);
  if (clamp_coupled_elements_.empty()) return;
  const PosesAt poses(clamps_, t);
  for (int e : clamp_coupled_elements_) {
    const auto& el = elements_[e];
    const double m = density_[e] * el.volume / 20;
    for (int b = 0; b < 4; ++b) {
      const int c = clamp_of_node_[el.nodes[b]];
      if (c < 0) continue;
      const Eigen::Vector3d acc = poses[c].acceleration(mesh_.nodes.col(el.nodes[b]));
      for (int a = 0; a < 4; ++a)
        for (int i = 0; i < 3; ++i)
          if (dof(el.nodes[a], i) >= 0) out[dof(el.nodes[a], i)] += m * acc[i];
    }
  }
}

void FemModel::mass_multiply(const double* x, double* y) const {
  if (lumped_) {
    parallel_for(n_, [&](int d) { y[d] += mass_diagonal_[d] * x[d]; });
    return;
  }
  // M is symmetric: row d of M x is column d of M against x, a gather per dof.
  parallel_for(n_, [&](int d) {
    double sum = 0;
    for (int k = pattern_.colptr[d]; k < pattern_.colptr[d + 1]; ++k)
      sum += mass_[k] * x[pattern_.rowind[k]];
    y[d] += sum;
  });
}

bool FemModel::evaluate_element(int e, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                unsigned request, ElementResponse& out, const double* z) const {
  const auto& el = elements_[e];
  Eigen::Matrix<double, 3, 4> xe, ve;
  for (int a = 0; a < 4; ++a) {
    xe.col(a) = x.col(el.nodes[a]);
    ve.col(a) = v.col(el.nodes[a]);
  }
  MaterialPoint mp;
  mp.F = xe * el.G.transpose();
  mp.Fdot = ve * el.G.transpose();
  mp.element = e;
  mp.rest_tangent = rest_tangent_.empty() ? nullptr : &rest_tangent_[e];
  out.P.setZero();
  out.mass_damping = 0;
  out.energy = 0;
  if (request & kTangent) out.dPdF.setZero();
  if (request & kRateTangent) out.dPdFdot.setZero();
  if (request & kParamDerivative) out.dPdq.resize(terms_.size());
  MaterialResponse& resp = out.term;
  for (const auto& term : terms_) {
    const int t = static_cast<int>(&term - terms_.data());
    if (internal_base_[t] >= 0) {
      if (!z) {
        // Relaxed: no stress, and nothing of dP/dq either (sized for the caller).
        if (request & kParamDerivative)
          out.dPdq[t].setZero(9, static_cast<int>(term.model->params().size()));
        continue;
      }
      mp.internal = z + internal_base_[t] + term.model->internal_size() * e;
    } else {
      mp.internal = nullptr;
    }
    const bool viscous = term.model->is_viscous();
    unsigned r = request;
    if (viscous)
      r &= ~static_cast<unsigned>(kEnergy);
    else
      r &= ~static_cast<unsigned>(kRateTangent);
    mp.q = term.q.col(e).data();
    mp.state = term.state.size() ? term.state.col(e).data() : nullptr;
    if (!term.model->evaluate(mp, r, resp)) {
      out.det_F = mp.F.determinant();
      return false;
    }
    out.P += resp.P;
    if (const int k = term.model->mass_damping_param(); k >= 0) out.mass_damping += mp.q[k];
    if (r & kTangent) out.dPdF += resp.dPdF;
    if (r & kRateTangent) out.dPdFdot += resp.dPdFdot;
    if (r & kEnergy) out.energy += resp.energy;
    if (r & kParamDerivative) out.dPdq[&term - terms_.data()] = resp.dPdq;
  }
  if (!out.P.allFinite()) {
    out.det_F = mp.F.determinant();
    return false;
  }
  return true;
}

bool FemModel::assemble(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                        const AssemblyRequest& req, AssemblyOutput& out, const double* z) const {
  const int ne = mesh_.num_tets();
  ElementSlots& slots = out.slots;
  if (req.force) slots.vector_a.resize(12 * static_cast<size_t>(ne));
  if (req.stiffness) slots.matrix_a.resize(144 * static_cast<size_t>(ne));
  if (req.damping) slots.matrix_b.resize(144 * static_cast<size_t>(ne));
  if (req.energy) out.cell_energy.resize(ne);
  out.energy = 0;

  unsigned request = kStress;
  if (req.stiffness) request |= kTangent;
  if (req.damping) request |= kRateTangent;
  if (req.energy) request |= kEnergy;

  const auto [failed, det] =
      for_each_element(x, v, z, request, slots.scratch, [&](int e, const ElementResponse& er) {
        const auto& el = elements_[e];
        if (req.energy) out.cell_energy[e] = er.energy;
        if (req.force) {
          Eigen::Map<Eigen::Matrix<double, 3, 4>> fe(&slots.vector_a[12 * static_cast<size_t>(e)]);
          fe = el.volume * er.P * el.G;
          if (er.mass_damping != 0) {
            Eigen::Matrix<double, 3, 4> ve;
            for (int a = 0; a < 4; ++a) ve.col(a) = v.col(el.nodes[a]);
            fe += er.mass_damping * element_mass_times(e, ve);
          }
        }
        Eigen::Matrix<double, 12, 12> Ke;
        if (req.stiffness) {
          Ke.setZero();
          accumulate_element_matrix(el, er.dPdF, 1.0, Ke);
          std::copy(Ke.data(), Ke.data() + 144, &slots.matrix_a[144 * static_cast<size_t>(e)]);
        }
        if (req.damping) {
          Ke.setZero();
          accumulate_element_matrix(el, er.dPdFdot, 1.0, Ke);
          if (er.mass_damping != 0) Ke += er.mass_damping * element_mass(e);
          std::copy(Ke.data(), Ke.data() + 144, &slots.matrix_b[144 * static_cast<size_t>(e)]);
        }
      });
  out.failed_element = failed;
  out.failed_det = det;
  if (failed >= 0) return false;
  if (req.force) {
    out.force.resize(n_);
    gather(dof_ptr_, dof_src_, slots.vector_a.data(), out.force.data());
  }
  if (req.stiffness) {
    out.K.resize(pattern_.nnz());
    gather(entry_ptr_, entry_src_, slots.matrix_a.data(), out.K.data());
  }
  if (req.damping) {
    out.D.resize(pattern_.nnz());
    gather(entry_ptr_, entry_src_, slots.matrix_b.data(), out.D.data());
  }
  if (req.energy)
    for (int e = 0; e < ne; ++e) out.energy += elements_[e].volume * out.cell_energy[e];
  if (!clamp_faces_.empty()) add_clamp_springs(x, v, req, out);
  return true;
}

bool FemModel::element_tangents(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                ElementTangents& out, bool param_derivatives,
                                const double* z) const {
  const int ne = mesh_.num_tets();
  out.dPdF.resize(ne);
  out.dPdFdot.resize(ne);
  out.mass_damping.resize(ne);
  out.dPdq.resize(param_derivatives ? ne : 0);
  const unsigned request =
      kStress | kTangent | kRateTangent | (param_derivatives ? kParamDerivative : 0u);
  const auto [failed, det] =
      for_each_element(x, v, z, request, out.scratch, [&](int e, const ElementResponse& er) {
        out.dPdF[e] = er.dPdF;
        out.dPdFdot[e] = er.dPdFdot;
        out.mass_damping[e] = er.mass_damping;
        if (param_derivatives) out.dPdq[e] = er.dPdq;
      });
  out.failed_element = failed;
  out.failed_det = det;
  return failed < 0;
}

void FemModel::assemble_tangents(const ElementTangents& t, std::vector<double>& K,
                                 std::vector<double>& D, ElementSlots& slots) const {
  const int ne = mesh_.num_tets();
  slots.matrix_a.resize(144 * static_cast<size_t>(ne));
  slots.matrix_b.resize(144 * static_cast<size_t>(ne));
  parallel_for(ne, [&](int e) {
    const auto& el = elements_[e];
    Eigen::Matrix<double, 12, 12> Ke = Eigen::Matrix<double, 12, 12>::Zero();
    accumulate_element_matrix(el, t.dPdF[e], 1.0, Ke);
    std::copy(Ke.data(), Ke.data() + 144, &slots.matrix_a[144 * static_cast<size_t>(e)]);
    Ke.setZero();
    accumulate_element_matrix(el, t.dPdFdot[e], 1.0, Ke);
    if (t.mass_damping[e] != 0) Ke += t.mass_damping[e] * element_mass(e);
    std::copy(Ke.data(), Ke.data() + 144, &slots.matrix_b[144 * static_cast<size_t>(e)]);
  });
  K.resize(pattern_.nnz());
  D.resize(pattern_.nnz());
  gather(entry_ptr_, entry_src_, slots.matrix_a.data(), K.data());
  gather(entry_ptr_, entry_src_, slots.matrix_b.data(), D.data());
  add_clamp_spring_matrices(&K, &D);
}

void FemModel::transpose_multiply(const ElementTangents& t, const double* lambda, double* Kt,
                                  double* Dt, ElementSlots& slots) const {
  const int ne = mesh_.num_tets();
  slots.vector_a.resize(12 * static_cast<size_t>(ne));
  slots.vector_b.resize(12 * static_cast<size_t>(ne));
  parallel_for(ne, [&](int e) {
    const auto& el = elements_[e];
    Eigen::Matrix<double, 3, 4> le;
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i) {
        const int d = dof(el.nodes[a], i);
        le(i, a) = d >= 0 ? lambda[d] : 0.0;
      }
    Eigen::Map<Eigen::Matrix<double, 3, 4>> kt(&slots.vector_a[12 * static_cast<size_t>(e)]);
    Eigen::Map<Eigen::Matrix<double, 3, 4>> dt(&slots.vector_b[12 * static_cast<size_t>(e)]);
    Eigen::Matrix<double, 3, 4> product;
    element_transpose_product(el, t.dPdF[e], le, product);
    kt = product;
    element_transpose_product(el, t.dPdFdot[e], le, product);
    dt = product;
    if (t.mass_damping[e] != 0) {
      dt += t.mass_damping[e] * element_mass_times(e, le);
    }
  });
  gather(dof_ptr_, dof_src_, slots.vector_a.data(), Kt);
  gather(dof_ptr_, dof_src_, slots.vector_b.data(), Dt);
  // The springs' S/c and dashpots' τ S/c are symmetric: Sᵀλ = Sλ.
  for (const auto& f : clamp_faces_) {
    const ClampBinding& c = clamps_[f.clamp];
    for (int a = 0; a < 3; ++a) {
      const Eigen::Vector3d sum = face_product(f, a, [&](int b) {
        return Eigen::Vector3d(lambda[dof(f.nodes[b], 0)], lambda[dof(f.nodes[b], 1)],
                               lambda[dof(f.nodes[b], 2)]);
      });
      for (int i = 0; i < 3; ++i) {
        Kt[dof(f.nodes[a], i)] += sum[i] / c.compliance;
        Dt[dof(f.nodes[a], i)] += sum[i] * c.damping_time / c.compliance;
      }
    }
  }
}

double FemModel::kinetic_energy(const Eigen::Matrix3Xd& v) const {
  if (lumped_)
    return 0.5 * (v.colwise().squaredNorm().transpose().array() * node_mass_.array()).sum();
  double ke = 0;
  for (int e = 0; e < mesh_.num_tets(); ++e) {
    const auto& el = elements_[e];
    const double m = density_[e] * el.volume / 20;
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        ke += 0.5 * m * (a == b ? 2 : 1) * v.col(el.nodes[a]).dot(v.col(el.nodes[b]));
  }
  return ke + 0.5 * (v.colwise().squaredNorm().transpose().array() * attached_mass_.array()).sum();
}

double FemModel::external_potential(const Eigen::Matrix3Xd& x) const {
  return -(node_mass_.transpose() * (gravity_.transpose() * x).transpose())(0) -
         (load_force_.array() * x.array()).sum();
}

}  // namespace kelvin
