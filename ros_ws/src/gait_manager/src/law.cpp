#include "gait_manager/law.hpp"

#include <utility>

namespace gait_manager
{

GaitManagerController::GaitManagerController(GaitManagerParameters params)
: params_(std::move(params))
{
}

void GaitManagerController::set_parameters(GaitManagerParameters params)
{
  params_ = std::move(params);
}

void GaitManagerController::compute(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  iceskate_native::ControllerOutput & out)
{
  out.clear();
  const iceskate_native::Mode & mode = kinematics.mode(obs.mode);
  const auto name = [](Source source) { return kSourceNames[static_cast<std::size_t>(source)]; };
  if (obs.t == 0.0 || !head_start_y_) {
    head_start_y_ =
      kinematics.frame_position(obs.support(), obs.q, iceskate_native::Frame::kHeadTop)[1];
  }
  if (enabled(Source::kPosture)) {
    auto & command = out.add(name(Source::kPosture));
    const PostureParameters & posture = params_.posture;
    if (posture.reference == PostureReference::kBalance) {
      balance_command(obs, kinematics, params_.balance, posture.yaw_stiffness,
                      posture.yaw_damping, *head_start_y_, command);
    } else {
      posture_command(obs, kinematics, posture, command);
    }
  }
  if (enabled(Source::kFeedforward)) {
    out.add(name(Source::kFeedforward))
      .set_torque(feedforward_torque(obs, mode, params_.feedforward));
  }
  if (enabled(Source::kWeightTransfer)) {
    out.add(name(Source::kWeightTransfer))
      .set_torque(weight_transfer_torque(obs, kinematics, params_.weight_transfer));
  }
  if (enabled(Source::kHeel)) {
    out.add(name(Source::kHeel)).set_torque(heel_torque(obs, mode, params_.heel));
  }
  if (enabled(Source::kArmAssist)) {
    out.add(name(Source::kArmAssist)).set_torque(arm_assist_torque(obs, params_.arm_assist));
  }
  if (enabled(Source::kYaw)) {
    out.add(name(Source::kYaw)).set_torque(yaw_torque(obs, params_.yaw));
  }
}

}  // namespace gait_manager
