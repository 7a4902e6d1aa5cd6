// The joint-space inertia matrix.
#pragma once

#include <Eigen/Core>

#include "iceskate_native/model.hpp"

namespace iceskate_native
{

/// M(q) by Pinocchio's CRBA, symmetrised (both triangles filled). q must have model.nq() finite
/// entries (std::invalid_argument otherwise).
Eigen::MatrixXd crba_of(const RobotModel & model, const Eigen::Ref<const Eigen::VectorXd> & q);

}  // namespace iceskate_native
