#include "iceskate_native/inertia.hpp"

#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/multibody.hpp>

#include "iceskate_native/checks.hpp"

namespace iceskate_native
{

Eigen::MatrixXd crba_of(const RobotModel & model, const Eigen::Ref<const Eigen::VectorXd> & q)
{
  require_finite_vector(q, model.nq(), "q", "model nq");
  const pinocchio::Model & pin_model = model.pin();
  pinocchio::Data data(pin_model);
  // q as Eigen::Ref<const VectorXd> selects the crba instantiation compiled into
  // libpinocchio_default (PINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION): this TU then compiles in
  // ~5 s instead of ~38 s. Keep passing Eigen::Ref<const VectorXd> to Pinocchio's algorithms.
  pinocchio::crba(pin_model, data, q);
  Eigen::MatrixXd inertia = data.M;
  inertia.triangularView<Eigen::StrictlyLower>() =
    inertia.transpose().triangularView<Eigen::StrictlyLower>();
  return inertia;
}

}  // namespace iceskate_native
