// The Large-Steps preconditioner (Nicolet, Jacobson, Jakob 2021, "Large Steps in Inverse
// Rendering of Geometry"): vertices x are optimised through u = (I + lambda L) x, where L is the
// combinatorial (uniform) Laplacian of the mesh (of the grid's triangulation for heightfields); x = M^-1 u is recovered with a sparse Cholesky
// factorisation of the symmetric positive definite M = I + lambda L (Eigen's SimplicialLLT),
// factorised once per mesh topology.
#pragma once
#include <memory>
#include <vector>

namespace limn {

class LargeSteps {
 public:
  // faces: 3 indices per triangle; throws std::invalid_argument for bad indices or lambda < 0.
  LargeSteps(const std::vector<uint32_t>& faces, size_t vertex_count, double lambda);
  ~LargeSteps();
  LargeSteps(LargeSteps&&) noexcept;
  LargeSteps& operator=(LargeSteps&&) noexcept;

  size_t vertex_count() const;
  // u = M x for row-major N x `columns` arrays (3 for vertex positions, 1 for heights).
  void to_u(const double* x, double* u, int columns = 3) const;
  // x = M^-1 u.
  void from_u(const double* u, double* x, int columns = 3) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m;
};

}  // namespace limn
