// Arm auxiliary input of steps 1-3 (docs/model.md §11.7): anti-phase shoulder sinusoid and an
// elbow/wrist PD to 0 before the 4th step, then a fading shoulder brake over release_time, then
// nothing. Its parameters: ArmAssistParameters (gait_manager/parameters.hpp, generated).
#pragma once

#include "gait_manager/parameters.hpp"
#include "gait_manager/phase.hpp"
#include "iceskate_native/controller.hpp"

namespace gait_manager
{

/// The arm assist [N m] on joints 11-16.
iceskate_native::Vector18 arm_assist_torque(
  const iceskate_native::Observation & obs, const ArmAssistParameters & params);

}  // namespace gait_manager
