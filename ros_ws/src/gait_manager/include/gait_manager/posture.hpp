// Posture stabiliser (docs/model.md §11.2): a PD of the driven joints to a reference posture,
// gravity compensation and the torso-yaw centring spring, optionally projected into the null
// space of the head Jacobian. The reference is the bent-knee standing posture, or the moving
// stance: the pelvis centre follows the stance schedule, reached by a planar 2-link IK of the
// support leg. Its parameters: PostureParameters (gait_manager/parameters.hpp, generated).
#pragma once

#include <Eigen/Core>

#include "gait_manager/parameters.hpp"
#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"
#include "iceskate_native/stance.hpp"

namespace gait_manager
{

/// q_ref (18 entries [m, rad]) and the head offset (dy, dz) [m] for visual lifting.
struct StanceReference
{
  iceskate_native::Vector18 q_ref = iceskate_native::Vector18::Zero();
  Eigen::Vector2d head_offset = Eigen::Vector2d::Zero();
};

/// The bent-knee standing posture q2..q7 = (-a, 2a, -a, a, -2a, a).
iceskate_native::Vector18 standing_posture(double bend);

/// World (y, z) [m] of the pelvis-centre target of the moving stance.
Eigen::Vector2d hip_target(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const PostureParameters & params);

/// (q2, q3, q4) [rad] putting the pelvis centre on `target` (world y, z) with the knee forward
/// and phi_4 = pelvis_pitch; an unreachable target gives the straight (or folded) leg.
Eigen::Vector3d support_leg_ik(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const PostureParameters & params, const Eigen::Vector2d & target);

StanceReference stance_reference(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const PostureParameters & params);

/// The stabiliser as a joint command: g(q) as effort, the PD and yaw spring as an impedance; with
/// null_space a torque held over the period (the PD depends on J_H). GaitManagerError when not
/// finite.
void posture_command(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const PostureParameters & params, iceskate_native::JointCommand & out);

/// tau_post [N m]: the whole stabiliser as a torque at the observed state.
iceskate_native::Vector18 posture_torque(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const PostureParameters & params);

}  // namespace gait_manager
