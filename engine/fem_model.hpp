#pragma once
/// \file
/// The spatially discretised solid: elements, material terms, mass, gravity and
/// clamps, with internal forces and tangents assembled into a sparsity pattern
/// computed once. Unknowns are the free nodal dofs (clamped nodes eliminated):
/// dof(node, i) ∈ [0, n) or −1 for a clamped node.
///
/// Sign convention: the "resisting force" r(x, v) = Σ_e V_e P_e G_e is minus the
/// internal force, so the equation of motion reads M v̇ + r(x, v) = f_ext, and
/// K = ∂r/∂x, D = ∂r/∂v are the stiffness and damping matrices.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "engine/body_force.hpp"
#include "engine/clamp_spring.hpp"
#include "engine/element.hpp"
#include "engine/mesh.hpp"
#include "engine/rigid_motion.hpp"
#include "materials/material.hpp"

namespace kelvin {

/// One additive constitutive term with its parameters per element (nq × tets) and
/// its fixed per-element state (state_size × tets, e.g. fibre directions).
struct MaterialTerm {
  std::shared_ptr<const Material> model;
  Eigen::MatrixXd q;
  Eigen::MatrixXd state;  // empty when the model has none
};

struct ClampBinding {
  std::string name;
  std::vector<int> nodes;
  std::shared_ptr<const RigidMotion> motion;
  /// > 0: a compliant clamp (engine/clamp_spring.hpp) whose nodes are unknowns held
  /// by pads of compliance c (m³/N) and retardation time τ (s); 0: rigid.
  double compliance = 0;
  double damping_time = 0;
  /// A probe pressed to a depth: its displacement from rest is part of the load, so
  /// static load steps (expand's `ramp`) scale it. Its motion must be a translation.
  bool ramped = false;
  bool compliant() const { return compliance > 0; }
};

/// A constant load carried by a set of nodes in equal shares: a force (N, total)
/// and an attached mass (kg, total) that adds inertia and, through gravity,
/// weight; a hanging weight is a mass. Clamped nodes carry no share.
struct NodeLoad {
  std::string name;
  std::vector<int> nodes;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  double mass = 0;
};

/// Symmetric CSC pattern over the free dofs, including the diagonal.
struct SparsePattern {
  int n = 0;
  std::vector<int> colptr, rowind;
  int nnz() const { return static_cast<int>(rowind.size()); }
  /// Value index of entry (row, col), which must be in the pattern (rows are
  /// sorted within each column).
  int find(int row, int col) const {
    const auto begin = rowind.begin() + colptr[col], end = rowind.begin() + colptr[col + 1];
    return static_cast<int>(std::lower_bound(begin, end, row) - rowind.begin());
  }
};

/// Values laid out in `pattern` as an Eigen sparse matrix (for direct solvers).
Eigen::SparseMatrix<double> to_sparse_matrix(const SparsePattern& pattern,
                                             const std::vector<double>& values);

/// The tangents of one element summed over its material terms at one state.
struct ElementResponse {
  Mat3 P;
  Mat9 dPdF, dPdFdot;
  double mass_damping = 0;  // α of the α M v force
  double energy = 0;        // Ψ (energy density)
  double det_F = 0;         // set when the element is inadmissible
  std::vector<Mat9X> dPdq;  // per material term, when kParamDerivative was requested
  /// One term's response, reused from element to element: built afresh per element
  /// it zeroed two 9×9 matrices and allocated dP/dq every time.
  MaterialResponse term;
};

/// Per-element results of an element loop before they are gathered into global
/// vectors and matrices, and each thread's scratch: kept between calls so that a
/// time step allocates nothing. Elements are evaluated in parallel (OpenMP) into
/// their own slots; every global entry then sums its slots in ascending element
/// order (FemModel's gather plan), so the result does not depend on the thread count.
struct ElementSlots {
  std::vector<double> vector_a, vector_b;  // 12 per element (local dof 3a + i)
  std::vector<double> matrix_a, matrix_b;  // 144 per element (column-major 12 × 12)
  std::vector<ElementResponse> scratch;    // one per thread
};

struct AssemblyRequest {
  bool force = true;
  bool stiffness = false;  // K values
  bool damping = false;    // D values
  bool energy = false;     // per-cell strain energy density and total elastic energy
};

struct AssemblyOutput {
  Eigen::VectorXd force;        // r over free dofs
  std::vector<double> K, D;     // values in pattern() order
  Eigen::VectorXd cell_energy;  // Ψ per tet (energy density, J/m³)
  double energy = 0;            // Σ V Ψ
  int failed_element = -1;      // set when a material reported an inadmissible state
                                // (the lowest such element)
  double failed_det = 0;        // det F of that element
  ElementSlots slots;           // workspace
};

/// Per-element tangents at one state, kept so that the adjoint can form Kᵀλ and
/// Dᵀλ element by element for every residual and assemble K and D only when IDAS
/// asks for a new Newton matrix.
struct ElementTangents {
  std::vector<Mat9> dPdF, dPdFdot;
  std::vector<double> mass_damping;
  /// [element][term] dP/dq, when asked for: the adjoint's quadrature contracts them
  /// with λ at the same state, so one material evaluation serves both.
  std::vector<std::vector<Mat9X>> dPdq;
  int failed_element = -1;
  double failed_det = 0;
  std::vector<ElementResponse> scratch;  // one per thread (workspace)
};

/// One element's internal variables of one material term (MaterialTerm::model with
/// internal_size() > 0): z[offset … offset + size) of the model's internal state.
struct InternalBlock {
  int term = 0, element = 0, offset = 0, size = 0;
};

/// The internal variables' law ż = f(F(x), z; q) at one state, and per block its
/// linearisation: what the element's resisting force r_e owes to z, and f to the
/// element's nodes, to z and to the parameters.
struct InternalLinearisation {
  Eigen::VectorXd rate;                                        // f over all internal variables
  std::vector<Eigen::Matrix<double, 12, Eigen::Dynamic>> Kxz;  // ∂r_e/∂z_b (dofs 3a + i)
  std::vector<Eigen::Matrix<double, Eigen::Dynamic, 12>> fx;   // ∂f_b/∂x_e
  std::vector<Eigen::MatrixXd> fz;                             // ∂f_b/∂z_b
  std::vector<Eigen::MatrixXd> fq;  // ∂f_b/∂q (the term's parameters)
  std::vector<char> coupled;        // Kxz ≠ 0: the branch carries stress
  /// Per thread, reused from call to call so that a step does not allocate.
  std::vector<InternalResponse> evolution;
  std::vector<MaterialResponse> response;
};

class FemModel {
 public:
  FemModel(const Mesh& mesh, std::vector<MaterialTerm> terms, Eigen::VectorXd density,
           Eigen::Vector3d gravity, std::vector<ClampBinding> clamps, bool lumped_mass,
           const std::vector<NodeLoad>& loads = {});

  const Mesh& mesh() const { return mesh_; }
  int num_dofs() const { return n_; }
  int dof(int node, int i) const { return dof_[3 * node + i]; }
  const SparsePattern& pattern() const { return pattern_; }
  const std::vector<TetElement>& elements() const { return elements_; }
  const std::vector<MaterialTerm>& terms() const { return terms_; }
  std::vector<MaterialTerm>& terms() { return terms_; }
  const std::vector<ClampBinding>& clamps() const { return clamps_; }
  bool lumped_mass() const { return lumped_; }
  /// Mass matrix values in pattern() order (diagonal only for lumped mass).
  const std::vector<double>& mass() const { return mass_; }
  /// External force on the free dofs: gravity (row sums of the full mass matrix,
  /// attached masses included, times g) plus the loads' forces.
  const Eigen::VectorXd& external_force() const { return f_external_; }
  const Eigen::Vector3d& gravity() const { return gravity_; }
  const Eigen::VectorXd& density() const { return density_; }
  /// Replaces the density field (per tet) and rebuilds mass and gravity.
  void set_density(Eigen::VectorXd density);
  /// C₀ of element e, or null when no term needs rest tangents.
  const Mat9* rest_tangent(int e) const {
    return rest_tangent_.empty() ? nullptr : &rest_tangent_[e];
  }

  /// Full nodal positions and velocities at time t from the free-dof vectors
  /// (clamped nodes follow their motion; ramped clamps `ramp` of their translation).
  void expand(double t, const double* x_free, const double* v_free, Eigen::Matrix3Xd& x,
              Eigen::Matrix3Xd& v, double ramp = 1.0) const;
  /// Full nodal accelerations at time t: a_free on free dofs, the clamp motion's
  /// acceleration on clamped nodes.
  void expand_acceleration(double t, const double* a_free, Eigen::Matrix3Xd& a) const;
  /// Free-dof vector of a full nodal field.
  void restrict(const Eigen::Matrix3Xd& full, double* free) const;
  /// M_fc a_c: inertia of the free dofs coupled to clamp accelerations (zero for
  /// lumped mass, where M has no free–clamped entries).
  void clamp_inertia(double t, Eigen::VectorXd& out) const;
  /// The compliant clamps' pull toward their motion over the free dofs,
  /// Σ S (x̂(t) + τ v̂(t))/c (v̂ only `with_velocity`): the part of their pads' force
  /// that does not depend on the state, which the residual subtracts (assemble() adds
  /// the part Σ S (x + τ v)/c that does).
  void clamp_pull(double t, bool with_velocity, Eigen::VectorXd& out) const;
  /// Elastic energy of the pads, ½ Σ (x − x̂)ᵀ S (x − x̂)/c: apart from assemble()'s
  /// energy, which it would swamp (a stiff pad's ½ xᵀ S x/c is 10¹² times the body's).
  double clamp_spring_energy(double t, const Eigen::Matrix3Xd& x) const;
  /// The faces the compliant clamps hold, in element order.
  const std::vector<ClampFace>& clamp_faces() const { return clamp_faces_; }
  /// Sets a compliant clamp's compliance (> 0).
  void set_clamp_compliance(int clamp, double compliance);
  /// A fitted body-force field (per unit mass; inactive unless configured).
  const BodyForceField& body_force() const { return body_force_; }
  BodyForceField& body_force() { return body_force_; }
  /// The body-force field's load on the free dofs at t: element e's ρ_e V_e/4 a(e, t)
  /// on each of its nodes (M_e times a uniform acceleration, lumped or consistent).
  void body_force_load(double t, Eigen::VectorXd& out) const;
  /// y += M x over the free dofs.
  void mass_multiply(const double* x, double* y) const;

  /// Assembles the requested quantities at full positions x and velocities v, and
  /// internal variables z (null: terms with internal variables are relaxed and carry
  /// nothing, as in static equilibrium). Returns false (with failed_element set) when
  /// some element is inadmissible.
  bool assemble(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, const AssemblyRequest& req,
                AssemblyOutput& out, const double* z = nullptr) const;

  /// Per-element tangents (and, with param_derivatives, every term's dP/dq) at full
  /// positions x, velocities v and internal variables z (as for assemble); false
  /// (with failed_element set) when some element is inadmissible.
  bool element_tangents(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, ElementTangents& out,
                        bool param_derivatives = false, const double* z = nullptr) const;

  /// Internal variables (materials with internal_size() > 0, e.g. a relaxing branch):
  /// how many, and their blocks in term-then-element order. They join the
  /// integrated state after the velocities (DaeSystem).
  int num_internal() const { return num_internal_; }
  const std::vector<InternalBlock>& internal_blocks() const { return internal_blocks_; }
  /// Index into internal_blocks() of term t's variables in element e, or −1.
  int internal_block(int t, int e) const {
    return internal_first_block_[t] < 0 ? -1 : internal_first_block_[t] + e;
  }
  /// z relaxed at full positions x (every block's f = 0 with x held): the state of a
  /// body that starts at rest or in equilibrium.
  void relaxed_internal(const Eigen::Matrix3Xd& x, double* z) const;
  /// The change of the relaxed z along a change dx of the free dofs,
  /// dz = −f_z⁻¹ f_x dx (for laws whose relaxed z does not depend on q).
  void relaxed_internal_change(const Eigen::Matrix3Xd& x, const double* dx_free, double* dz) const;
  /// Its transpose: out_free += (∂z/∂x)ᵀ lz (the adjoint's initial condition).
  void relaxed_internal_change_transpose(const Eigen::Matrix3Xd& x, const double* lz,
                                         double* out_free) const;
  /// Per internal variable, how much its error matters: its block's stiffness at rest
  /// over the element's elastic stiffness at rest (‖∂P/∂F‖ at F = I), at most 1. A
  /// branch at zero modulus gets 0 and leaves the integrator's error test, so that it
  /// steps exactly as the model without it.
  Eigen::VectorXd internal_error_share() const;
  /// f at (x, v, z) and, with request kTangent / kParamDerivative, its linearisation;
  /// false when a term rejects the state.
  bool linearise_internal(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, const double* z,
                          unsigned request, InternalLinearisation& out) const;
  /// values += A (element e's 12 × 12 matrix, dofs 3a + i) over its free entries of
  /// the pattern.
  void scatter_element_matrix(int e, const Eigen::Matrix<double, 12, 12>& A, double* values) const;
  /// Free dof of element e's local dof k = 3a + i, or −1 for a clamped one.
  int element_dof(int e, int k) const { return dof(elements_[e].nodes[k / 3], k % 3); }
  /// Element e's 12 values of a free-dof vector (0 at clamped dofs), and the
  /// scatter-add of 12 element values into one.
  Eigen::Matrix<double, 12, 1> element_values(int e, const double* free) const {
    Eigen::Matrix<double, 12, 1> v;
    for (int k = 0; k < 12; ++k) {
      const int d = element_dof(e, k);
      v[k] = d >= 0 ? free[d] : 0.0;
    }
    return v;
  }
  void add_element_values(int e, const Eigen::Matrix<double, 12, 1>& v, double* free) const {
    for (int k = 0; k < 12; ++k)
      if (const int d = element_dof(e, k); d >= 0) free[d] += v[k];
  }
  /// K and D values in pattern() order from element tangents.
  void assemble_tangents(const ElementTangents& t, std::vector<double>& K, std::vector<double>& D,
                         ElementSlots& slots) const;
  /// Kt = Kᵀλ and Dt = Dᵀλ over the free dofs, element by element.
  void transpose_multiply(const ElementTangents& t, const double* lambda, double* Kt, double* Dt,
                          ElementSlots& slots) const;

  /// The element with the smallest det F at full positions x, and that det F.
  std::pair<int, double> most_compressed_element(const Eigen::Matrix3Xd& x) const;

  /// Recomputes the elastic rest tangents C₀ (∂P/∂F at F = I per element) that
  /// stiffness-proportional damping uses; call after changing elastic parameters.
  void update_rest_tangents();

  /// 12×12 mass matrix of element e (dof order 3a + i), lumped or consistent.
  Eigen::Matrix<double, 12, 12> element_mass(int e) const;
  /// element_mass(e) times the nodal values u (one column per node), in closed form:
  /// mass-proportional damping applies it to every element at every residual.
  Eigen::Matrix<double, 3, 4> element_mass_times(int e, const Eigen::Matrix<double, 3, 4>& u) const;

  /// Kinetic energy ½ vᵀ M v over all nodes (clamped included) for full velocities.
  double kinetic_energy(const Eigen::Matrix3Xd& v) const;
  /// Potential of the external forces, −Σ (m_a g + f_a)·x_a, for full positions.
  double external_potential(const Eigen::Matrix3Xd& x) const;

  /// P, the requested tangents (kTangent, kRateTangent) and energy of element e,
  /// summed over the material terms (those with internal variables only when z is
  /// given); false when a term rejects the state.
  bool evaluate_element(int e, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                        unsigned request, ElementResponse& out, const double* z = nullptr) const;

 private:
  void build_pattern();
  void build_gather_plan();
  void build_mass();
  /// Adds the compliant clamps' state-dependent spring and dashpot terms.
  void add_clamp_springs(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                         const AssemblyRequest& req, AssemblyOutput& out) const;
  void add_clamp_spring_matrices(std::vector<double>* K, std::vector<double>* D) const;
  /// Sums element slots into global values: out[d] = Σ slots[src] over gather list d.
  void gather(const std::vector<int>& ptr, const std::vector<int>& src, const double* slots,
              double* out) const;
  /// Evaluates elements in parallel: body(e, response) for each, with `request`;
  /// returns the lowest failing element (−1 when none) and its det F.
  template <class Body>
  std::pair<int, double> for_each_element(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                          const double* z, unsigned request,
                                          std::vector<ElementResponse>& scratch, Body body) const;
  void number_internal_variables();
  /// linearise_internal at the z relaxed at x.
  InternalLinearisation relaxed_linearisation(const Eigen::Matrix3Xd& x) const;
  /// The material point of block b at full positions x (F, q, state; internal from z).
  MaterialPoint internal_point(const InternalBlock& b, const Eigen::Matrix3Xd& x,
                               const double* z) const;

  const Mesh& mesh_;
  std::vector<MaterialTerm> terms_;
  Eigen::VectorXd density_;  // per tet
  Eigen::Vector3d gravity_;
  std::vector<ClampBinding> clamps_;
  bool lumped_;
  Eigen::VectorXd attached_mass_;  // per node, from the loads
  Eigen::Matrix3Xd load_force_;    // per node, from the loads
  std::vector<TetElement> elements_;
  std::vector<int> dof_;            // 3 × nodes → free dof or −1
  std::vector<int> clamp_of_node_;  // clamp index or −1
  int n_ = 0;
  SparsePattern pattern_;
  std::vector<int> scatter_;  // per element 12×12 → pattern value index or −1
  // Gather plan: for free dof d, the element vector slots (12e + k) that sum into it,
  // dof_src_[dof_ptr_[d] … dof_ptr_[d+1]); for pattern entry p, the matrix slots
  // (144e + k), entry_src_[entry_ptr_[p] …]; both in ascending element order.
  std::vector<int> dof_ptr_, dof_src_, entry_ptr_, entry_src_;
  std::vector<double> mass_;           // pattern values
  std::vector<double> mass_diagonal_;  // per free dof
  Eigen::VectorXd node_mass_;          // lumped nodal masses (all nodes, attached masses included)
  Eigen::VectorXd f_external_;
  std::vector<int> clamp_coupled_elements_;  // elements with free and clamped nodes
  std::vector<ClampFace> clamp_faces_;       // of the compliant clamps
  std::vector<int> clamp_face_entries_;      // per face 3 × 3 node pairs: K's diagonal-block entry
  std::vector<Mat9> rest_tangent_;           // per element, only when some term needs it
  BodyForceField body_force_;
  int num_internal_ = 0;
  std::vector<int> internal_base_;         // per term: its first internal variable, or −1
  std::vector<int> internal_first_block_;  // per term: its first internal block, or −1
  std::vector<InternalBlock> internal_blocks_;
};

}  // namespace kelvin
