#pragma once
/// \file
/// Principal-stretch machinery shared by the isotropic models written in terms of
/// the singular values of F (corotational, spline):
///
///   F = U Σ Vᵀ with U, V proper rotations ("sign-fixed" SVD, Irving, Teran &
///   Fedkiw 2004): a reflection is absorbed into the smallest singular value, which
///   goes negative for an inverted element, so Ψ(Σ) stays well defined there.
///
/// For an isotropic energy Ψ(σ₁, σ₂, σ₃) with p = ∂Ψ/∂σ and H = ∂²Ψ/∂σ²,
///   P = U diag(p) Vᵀ
/// and the tangent in the rotated frame (δF̂ = Uᵀ δF V, δP̂ = Uᵀ δP V) decouples into
/// the 3×3 block H on the diagonal entries and, for each pair i ≠ j, a 2×2 block on
/// (F̂ᵢⱼ, F̂ⱼᵢ) (Teran, Sifakis, Irving & Fedkiw 2005, "Robust quasistatic finite
/// elements and flesh simulation", eq. 5; Xu, Sin, Zhu & Barbič 2015):
///   [a b; b a],  a = (σᵢpᵢ − σⱼpⱼ)/(σᵢ² − σⱼ²),  b = (σⱼpᵢ − σᵢpⱼ)/(σᵢ² − σⱼ²).
/// Both are evaluated as ½(d ± s) with d = (pᵢ − pⱼ)/(σᵢ − σⱼ) and
/// s = (pᵢ + pⱼ)/(σᵢ + σⱼ): the caller supplies d in a form that stays finite for
/// σᵢ → σⱼ (its L'Hôpital limit), which removes the repeated-stretch singularity.
/// s remains singular where σᵢ = −σⱼ, i.e. only for inverted elements.
#include <Eigen/Core>

#include "materials/material.hpp"

namespace kelvin {

struct SignedSvd {
  Mat3 U, V;              // proper rotations (det = +1)
  Eigen::Vector3d sigma;  // descending |σ|; σ₃ < 0 when det F < 0
};

SignedSvd signed_svd(const Mat3& F);

/// Pairs (i, j) in the order used for the divided differences: (0,1), (0,2), (1,2).
inline constexpr int kSvdPairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};

/// U diag(p) Vᵀ.
Mat3 principal_stress(const SignedSvd& svd, const Eigen::Vector3d& p);

/// dP/dF (column-major vec layout of material.hpp) of P = U diag(p(σ)) Vᵀ.
/// `divided[k]` = (p_i − p_j)/(σ_i − σ_j) for pair kSvdPairs[k], evaluated stably.
Mat9 principal_tangent(const SignedSvd& svd, const Eigen::Vector3d& p, const Mat3& H,
                       const Eigen::Vector3d& divided);

}  // namespace kelvin
