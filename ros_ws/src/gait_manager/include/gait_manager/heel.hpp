// Heel-first landing input on the swing ankle, joint 7 (docs/model.md §11.6): in the air a PD of
// the swing-sole pitch to a landing pitch ramped in after t_e; heel on the floor, a softer PD to
// a flat sole; sole flat, nothing. The counterpart of gait_manager/heel.py.
#pragma once

#include "iceskate_native/controller.hpp"

namespace gait_manager
{

/// HeelParameters (gait_manager/heel.py, the one schema).
struct HeelParameters
{
  double stiffness = 0.0;          ///< K7 in the air [N m/rad]
  double damping = 0.0;            ///< B7 in the air [N m s/rad]
  double landing_pitch = 0.0;      ///< theta_land [rad]
  double ramp_time = 0.0;          ///< [s]
  double contact_stiffness = 0.0;  ///< heel on the floor [N m/rad]
  double contact_damping = 0.0;    ///< heel on the floor [N m s/rad]
};

/// The heel-first input [N m]: only entry 7 (swing ankle) can be nonzero.
iceskate_native::Vector18 heel_torque(
  const iceskate_native::Observation & obs, const iceskate_native::Mode & mode,
  const HeelParameters & params);

}  // namespace gait_manager
