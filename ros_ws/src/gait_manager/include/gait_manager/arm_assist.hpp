// Arm auxiliary input of steps 1-3 (docs/model.md §11.7): anti-phase shoulder sinusoid and an
// elbow/wrist PD to 0 before the 4th step, then a fading shoulder brake over release_time, then
// nothing. The counterpart of gait_manager/arm_assist.py.
#pragma once

#include "gait_manager/phase.hpp"
#include "iceskate_native/controller.hpp"

namespace gait_manager
{

/// ArmAssistParameters (gait_manager/arm_assist.py, the one schema).
struct ArmAssistParameters
{
  double amplitude = 0.0;  ///< A_arm [N m]
  double period = 0.0;     ///< T [s]
  PhaseReading phase = PhaseReading::kB;
  double stiffness = 0.0;  ///< elbow and wrist PD [N m/rad]
  double damping = 0.0;    ///< [N m s/rad]
  int off_from_step_index = 0;  ///< the assist stops from this many exchanges on
  double release_time = 0.0;     ///< shoulder brake after the assist stops [s]
  double release_damping = 0.0;  ///< its initial damping [N m s/rad]
};

/// The arm assist [N m] on joints 11-16.
iceskate_native::Vector18 arm_assist_torque(
  const iceskate_native::Observation & obs, const ArmAssistParameters & params);

}  // namespace gait_manager
