// Heel-first landing input on the swing ankle, joint 7 (docs/model.md §11.6): in the air a PD of
// the swing-sole pitch to a landing pitch ramped in after t_e; heel on the floor, a softer PD to
// a flat sole; sole flat, nothing. Its parameters: HeelParameters (gait_manager/parameters.hpp,
// generated).
#pragma once

#include "gait_manager/parameters.hpp"
#include "iceskate_native/controller.hpp"

namespace gait_manager
{

/// The heel-first input [N m]: only entry 7 (swing ankle) can be nonzero.
iceskate_native::Vector18 heel_torque(
  const iceskate_native::Observation & obs, const iceskate_native::Mode & mode,
  const HeelParameters & params);

}  // namespace gait_manager
