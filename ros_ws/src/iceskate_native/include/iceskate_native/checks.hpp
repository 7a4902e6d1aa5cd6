// Argument checks at the boundary: every kernel validates its inputs before touching Pinocchio,
// and reports a bad one with std::invalid_argument (ValueError in Python) naming the argument.
#pragma once

#include <Eigen/Core>

namespace iceskate_native
{

/// Require `value` to have `expected` entries (`what` says where the length comes from, e.g.
/// "model nq") and every entry to be finite. `name` names the argument in the message.
void require_finite_vector(
  const Eigen::Ref<const Eigen::VectorXd> & value, Eigen::Index expected, const char * name,
  const char * what);

}  // namespace iceskate_native
