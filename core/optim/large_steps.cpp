#include "core/optim/large_steps.h"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <set>
#include <stdexcept>
#include <string>

namespace limn {

struct LargeSteps::Impl {
  size_t n = 0;
  Eigen::SparseMatrix<double> M;
  Eigen::SimplicialLLT<Eigen::SparseMatrix<double>> llt;
};

LargeSteps::LargeSteps(const std::vector<uint32_t>& faces, size_t n, double lambda) : m(std::make_unique<Impl>()) {
  if (!(lambda >= 0.0)) throw std::invalid_argument("LargeSteps: lambda must be >= 0 (got " + std::to_string(lambda) + ")");
  if (faces.size() % 3 != 0) throw std::invalid_argument("LargeSteps: faces must hold 3 indices per triangle");
  m->n = n;
  // Unique undirected edges; L = D - A (degree minus adjacency).
  std::set<std::pair<uint32_t, uint32_t>> edges;
  for (size_t t = 0; t < faces.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = faces[t + k], b = faces[t + (k + 1) % 3];
      if (a >= n || b >= n) throw std::invalid_argument("LargeSteps: face index " + std::to_string(std::max(a, b)) + " >= vertex count " + std::to_string(n));
      if (a == b) continue;
      edges.emplace(std::min(a, b), std::max(a, b));
    }
  std::vector<Eigen::Triplet<double>> trip;
  std::vector<double> degree(n, 0.0);
  for (const auto& [a, b] : edges) {
    trip.emplace_back(a, b, -lambda);
    trip.emplace_back(b, a, -lambda);
    degree[a] += 1.0;
    degree[b] += 1.0;
  }
  for (size_t i = 0; i < n; ++i) trip.emplace_back(int(i), int(i), 1.0 + lambda * degree[i]);
  m->M.resize(long(n), long(n));
  m->M.setFromTriplets(trip.begin(), trip.end());
  m->llt.compute(m->M);
  if (m->llt.info() != Eigen::Success) throw std::runtime_error("LargeSteps: Cholesky factorisation failed");
}

LargeSteps::~LargeSteps() = default;
LargeSteps::LargeSteps(LargeSteps&&) noexcept = default;
LargeSteps& LargeSteps::operator=(LargeSteps&&) noexcept = default;
size_t LargeSteps::vertex_count() const { return m->n; }

void LargeSteps::to_u(const double* x, double* u, int columns) const {
  const long n = long(m->n);
  using Rows = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::Map<const Rows> X(x, n, columns);
  Eigen::Map<Rows> U(u, n, columns);
  U = m->M * X;
}

void LargeSteps::from_u(const double* u, double* x, int columns) const {
  const long n = long(m->n);
  using Rows = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::Map<const Rows> U(u, n, columns);
  Eigen::Map<Rows> X(x, n, columns);
  const Eigen::MatrixXd Ucol = U;
  X = m->llt.solve(Ucol);
}

}  // namespace limn
