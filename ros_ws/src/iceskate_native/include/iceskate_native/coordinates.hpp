// The generalized coordinates [y0, q1, ..., q17] of every support model (docs/model.md §1.3)
// and the fixed-size vector over them. Eigen only: the controller interface builds on it.
#pragma once

#include <Eigen/Core>

namespace iceskate_native
{

constexpr int kCoordinates = 18;  // [y0, q1, ..., q17]
constexpr int kY0 = 0;
constexpr int kQ1 = 1;

/// A value per coordinate [y0, q1, ..., q17] (m, rad; N, N m; ...).
using Vector18 = Eigen::Matrix<double, kCoordinates, 1>;

}  // namespace iceskate_native
