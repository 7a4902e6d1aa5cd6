// Walking stabiliser, the 'balance' reference of the posture stabiliser (docs/model.md §11.3):
// trunk and support-leg PDs blended in after each exchange, a virtual forward force at the
// centre of mass for the speed, an ankle strategy, gravity compensation, the torso-yaw spring,
// a swing-ankle path with foot placement in the air, and push-off in double support. The
// counterpart of gait_manager/balance.py.
#pragma once

#include <utility>

#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"

namespace gait_manager
{

/// BalanceParameters (gait_manager/balance.py, the one schema; units there).
struct BalanceParameters
{
  double swing_time = 0.0;     ///< [s]
  double glide_time = 0.0;     ///< [s]
  double clearance = 0.0;      ///< [m]
  double press = 0.0;          ///< [m]
  double lift_fraction = 0.0;
  double descent_start = 0.0;
  double step_length = 0.0;    ///< [m]
  double placement_gain = 0.0; ///< [s]
  double speed = 0.0;          ///< v_d [m/s]
  double speed_gain = 0.0;     ///< k_v [N s/m]
  double pace_gain = 0.0;      ///< k_p [N/m]
  double feedback_limit = 0.0; ///< bound of the speed and pace terms [N] (0: none)
  double drive = 0.0;          ///< F_0 [N]
  double max_force = 0.0;      ///< [N]
  double max_brake = 0.0;      ///< [N]
  double com_stiffness = 0.0;  ///< [N m/m]
  double com_damping = 0.0;    ///< [N m s/m]
  double com_offset = 0.0;     ///< [m]
  double stance_knee = 0.0;    ///< [rad]
  double trunk = 0.0;          ///< [rad]
  double stiffness = 0.0;      ///< [N m/rad]
  double ankle_stiffness = 0.0;       ///< [N m/rad]
  double ankle_damping = 0.0;         ///< [N m s/rad]
  double swing_stiffness = 0.0;       ///< [N m/rad]
  double swing_damping = 0.0;         ///< [N m s/rad]
  double front_hip_stiffness = 0.0;   ///< [N m/rad]
  double front_knee_stiffness = 0.0;  ///< [N m/rad]
  double push = 0.0;           ///< [N m]
  double push_ramp = 0.0;      ///< [s]
  double toe_off_flex = 0.0;   ///< [rad]
  double blend = 0.0;          ///< [s]
  double front_knee_step = 0.0;  ///< [rad] (0: no bound)
};

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
