// Torso-yaw input of the paper's eq. (10) (docs/model.md §11.8): tau_8 = +A sin(Phi) while the
// right foot supports, -A sin(Phi) while the left does. The counterpart of gait_manager/yaw.py.
#pragma once

#include "gait_manager/phase.hpp"
#include "iceskate_native/controller.hpp"

namespace gait_manager
{

/// YawParameters (gait_manager/yaw.py, the one schema).
struct YawParameters
{
  double amplitude = 0.0;  ///< A [N m]
  double period = 0.0;     ///< T [s]
  PhaseReading phase = PhaseReading::kB;
};

/// The eq. (10) torque [N m]: only entry 8 (torso yaw) is nonzero.
iceskate_native::Vector18 yaw_torque(
  const iceskate_native::Observation & obs, const YawParameters & params);

}  // namespace gait_manager
