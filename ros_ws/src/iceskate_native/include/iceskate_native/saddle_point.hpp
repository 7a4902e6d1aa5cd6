// The eq. (7) system as a saddle point: [[M + e0 a^T, C], [D, 0]] [x; lambda] = [f; g], with M
// symmetric positive definite over the n active coordinates, a the rank-one change of its first
// row (the support's sliding friction, which grows with the vertical acceleration of the centre
// of mass; a = 0: none), and nc <= 3 constraint rows D and multiplier columns C (-D^T, changed
// where the swing heel slides and, in row 0, where the support slides). Solved by M's Cholesky
// factor, the Sherman-Morrison formula for a and the nc x nc Schur complement D B^-1 C: no
// blocked LU path at 18 + 3 unknowns (about a quarter fewer instructions than Eigen's LU there).
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>

#include "iceskate_native/coordinates.hpp"

namespace iceskate_native
{

constexpr int kMaxConstraints = 3;
constexpr int kMaxUnknowns = kCoordinates + kMaxConstraints;

/// The whole system matrix and its right-hand side (at most 21 unknowns).
using SystemMatrix =
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxUnknowns, kMaxUnknowns>;
using SystemVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxUnknowns, 1>;
/// A value per active coordinate (at most 18).
using ActiveVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kCoordinates, 1>;

class SaddlePoint
{
public:
  /// Factor `system` (size n + nc) whose top-left n x n block is M + e0 a^T (`row_change`: a,
  /// n entries, or empty for none). False when M is not positive definite, 1 + a^T M^-1 e0
  /// vanishes or the Schur complement is singular: the system then needs a general solver.
  bool factor(const SystemMatrix & system, int n, int nc, const ActiveVector & row_change);

  /// The unknowns [x; lambda] of the factored system for the right-hand side `rhs`.
  void solve(const SystemVector & rhs, SystemVector & unknowns) const;

private:
  using Mass = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kCoordinates, kCoordinates>;
  using Columns =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kCoordinates, kMaxConstraints>;
  using Rows =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxConstraints, kCoordinates>;
  using Schur =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxConstraints, kMaxConstraints>;

  /// B^-1 y in place, B = M + e0 a^T (Sherman-Morrison on M's factor).
  template <typename Block>
  void apply_inverse(Block && y) const;

  int n_ = 0;
  int nc_ = 0;
  bool changed_row_ = false;
  Mass mass_;
  Eigen::LLT<Mass> cholesky_;
  ActiveVector row_change_;  // a
  ActiveVector first_;       // M^-1 e0
  double denominator_ = 1.0;  // 1 + a^T M^-1 e0
  Rows rows_;               // D
  Columns inverse_columns_;  // B^-1 C
  Eigen::PartialPivLU<Schur> schur_;  // of D B^-1 C
};

}  // namespace iceskate_native
