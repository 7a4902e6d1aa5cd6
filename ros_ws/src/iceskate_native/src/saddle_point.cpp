#include "iceskate_native/saddle_point.hpp"

#include <cmath>

namespace iceskate_native
{

namespace
{

constexpr double kSingular = 1e-12;  // |1 + a^T M^-1 e0| below which the update is singular

}  // namespace

template <typename Block>
void SaddlePoint::apply_inverse(Block && y) const
{
  cholesky_.solveInPlace(y);
  if (changed_row_) {  // (M + e0 a^T)^-1 = M^-1 - M^-1 e0 a^T M^-1 / (1 + a^T M^-1 e0)
    for (Eigen::Index k = 0; k < y.cols(); ++k) {
      y.col(k) -= first_ * (row_change_.dot(y.col(k)) / denominator_);
    }
  }
}

bool SaddlePoint::factor(
  const SystemMatrix & system, int n, int nc, const ActiveVector & row_change)
{
  n_ = n;
  nc_ = nc;
  changed_row_ = row_change.size() > 0;
  mass_ = system.topLeftCorner(n, n);
  if (changed_row_) {  // only the lower triangle is read: of row 0, the diagonal
    row_change_ = row_change;
    mass_(0, 0) -= row_change[0];
  }
  cholesky_.compute(mass_);
  if (cholesky_.info() != Eigen::Success) {
    return false;
  }
  if (changed_row_) {
    first_ = ActiveVector::Unit(n, 0);
    cholesky_.solveInPlace(first_);
    denominator_ = 1.0 + row_change_.dot(first_);
    if (!(std::abs(denominator_) > kSingular)) {
      return false;
    }
  }
  if (nc == 0) {
    return true;
  }
  rows_ = system.bottomLeftCorner(nc, n);
  inverse_columns_ = system.topRightCorner(n, nc);
  apply_inverse(inverse_columns_);
  schur_.compute(rows_ * inverse_columns_);
  return (schur_.matrixLU().diagonal().array() != 0.0).all();
}

void SaddlePoint::solve(const SystemVector & rhs, SystemVector & unknowns) const
{
  unknowns.resize(n_ + nc_);
  auto x = unknowns.head(n_);
  x = rhs.head(n_);
  apply_inverse(x);
  if (nc_ > 0) {
    auto multipliers = unknowns.tail(nc_);
    multipliers = schur_.solve(rows_ * x - rhs.tail(nc_));
    x -= inverse_columns_ * multipliers;
  }
}

}  // namespace iceskate_native
