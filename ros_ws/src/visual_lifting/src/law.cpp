#include "visual_lifting/law.hpp"

#include <algorithm>
#include <utility>

namespace visual_lifting
{

using iceskate_native::stance_schedule;
using iceskate_native::Vector18;

Eigen::Vector3d desired_head_pose(
  const VisualLiftingParameters & params, double t, const Eigen::Vector3d & psi,
  const Eigen::Vector3d & origin, const Eigen::Vector2d & offset)
{
  double y_d = 0.0;
  switch (params.desired_y) {
    case DesiredYOption::kMoving:
      y_d = origin[0] + params.v_d * t + offset[0];
      break;
    case DesiredYOption::kFixed:
      y_d = origin[0] + offset[0];
      break;
    case DesiredYOption::kFollow:
      y_d = psi[0];
      break;
  }
  const double z_d = (params.z_d ? *params.z_d : origin[1]) + offset[1];
  return {y_d, z_d, params.pitch_d};
}

Eigen::Vector3d head_error(
  const VisualLiftingParameters & params, const Eigen::Vector3d & psi_d,
  const Eigen::Vector3d & psi)
{
  Eigen::Vector3d error = psi_d - psi;
  if (params.max_dy) {
    error[0] = std::min(std::max(error[0], -*params.max_dy), *params.max_dy);
  }
  return error;
}

VisualLiftingController::VisualLiftingController(VisualLiftingParameters params)
: params_(std::move(params))
{
}

void VisualLiftingController::set_parameters(VisualLiftingParameters params)
{
  params_ = std::move(params);
}

void VisualLiftingController::latch_origin(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics)
{
  origin_ = kinematics.head_pose(obs.support(), obs.q).psi;
}

void VisualLiftingController::compute(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  iceskate_native::ControllerOutput & out)
{
  const iceskate_native::HeadPose pose = kinematics.head_pose(obs.support(), obs.q);
  if (obs.t == 0.0 || !origin_) {
    origin_ = pose.psi;
  }
  const Eigen::Vector3d psi_d =
    desired_head_pose(params_, obs.t, pose.psi, *origin_, stance_schedule(params_).shift(obs));
  const Eigen::Vector3d kp(params_.kp[0], params_.kp[1], params_.kp[2]);
  const Eigen::Vector3d pull = kp.cwiseProduct(head_error(params_, psi_d, pose.psi));
  const Vector18 all = pose.jacobian.transpose() * pull;
  Vector18 tau = Vector18::Zero();
  const bool joint1 = kinematics.mode(obs.mode).q1_active && params_.joint1_torque;
  for (int joint : params_.joints) {
    if (joint > 1 || joint1) {
      tau[joint] = all[joint];
    }
  }
  out.clear();
  out.add("visual_lifting").set_torque(tau);
  out.has_head_target = true;
  out.head_target = psi_d;
}

}  // namespace visual_lifting
