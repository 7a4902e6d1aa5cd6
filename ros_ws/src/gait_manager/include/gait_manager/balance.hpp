// Walking stabiliser, the 'balance' reference of the posture stabiliser (docs/model.md §11.3):
// trunk and support-leg PDs blended in after each exchange, a virtual forward force at the
// centre of mass for the speed, an ankle strategy, gravity compensation, the torso-yaw spring,
// a swing-ankle path with foot placement in the air, and push-off in double support. Its
// parameters: BalanceParameters (gait_manager/parameters.hpp, generated).
#pragma once

#include <utility>

#include "gait_manager/parameters.hpp"
#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"

namespace gait_manager
{

/// World pitch angles (phi_thigh, phi_shank) [rad] of a hanging 2-link leg whose ankle is at
/// (d_y, d_z) [m] from the hip, knee forward; out of reach: the straight leg pointing there.
std::pair<double, double> leg_ik(double d_y, double d_z, double thigh, double shank);

/// World (y, z) [m] of the swing-ankle path at obs.t, from the hip's y and the CoM's y and
/// forward speed [m, m/s].
std::pair<double, double> swing_ankle_target(
  const iceskate_native::Observation & obs, const BalanceParameters & params, double hip_y,
  double com_y, double com_vy);

/// The walking stabiliser as a joint command (impedance + effort), with the torso-yaw spring
/// (yaw_stiffness [N m/rad], yaw_damping [N m s/rad]); head_start_y [m] is the head top's y at
/// t = 0, the start of the pace point. GaitManagerError when not finite.
void balance_command(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const BalanceParameters & params, double yaw_stiffness, double yaw_damping,
  double head_start_y, iceskate_native::JointCommand & out);

}  // namespace gait_manager
