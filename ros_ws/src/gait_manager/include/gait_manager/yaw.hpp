// Torso-yaw input of the paper's eq. (10) (docs/model.md §11.8): tau_8 = +A sin(Phi) while the
// right foot supports, -A sin(Phi) while the left does. Its parameters: YawParameters
// (gait_manager/parameters.hpp, generated).
#pragma once

#include "gait_manager/parameters.hpp"
#include "gait_manager/phase.hpp"
#include "iceskate_native/controller.hpp"

namespace gait_manager
{

/// The eq. (10) torque [N m]: only entry 8 (torso yaw) is nonzero.
iceskate_native::Vector18 yaw_torque(
  const iceskate_native::Observation & obs, const YawParameters & params);

}  // namespace gait_manager
