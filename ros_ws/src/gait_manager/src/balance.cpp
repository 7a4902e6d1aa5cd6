#include "gait_manager/balance.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "gait_manager/errors.hpp"
#include "iceskate_native/stance.hpp"

namespace gait_manager
{

namespace
{

constexpr double kAnkleHeight = 0.07;      // [m] ankle above the sole (docs/model.md §2.4)
constexpr double kThigh = 0.38;            // [m] leg link lengths (Table 1)
constexpr double kShank = 0.40;            // [m]
constexpr double kSwingStartBehind = 0.15;  // [m] start of the swing-ankle path behind the hip
constexpr double kFrontKnee = -0.05;       // [rad] front knee reference in double support
constexpr int kGravityJoints[] = {2, 3, 4, 9, 10};
constexpr int kSpeedJoints[] = {2, 3, 4};
constexpr int kAnkle = 2;     // support ankle q2
constexpr int kSwingHip = 5;  // swing hip q5

using iceskate_native::smoothstep;

}  // namespace

std::pair<double, double> leg_ik(double d_y, double d_z, double thigh, double shank)
{
  const double reach = std::min(std::hypot(d_y, d_z), thigh + shank - 1e-9);
  const double cos_knee = (reach * reach - thigh * thigh - shank * shank) / (2.0 * thigh * shank);
  const double knee = std::acos(std::min(std::max(cos_knee, -1.0), 1.0));
  const double direction = std::atan2(d_y, -d_z);
  const double phi_thigh =
    direction + std::atan2(shank * std::sin(knee), thigh + shank * std::cos(knee));
  return {phi_thigh, phi_thigh - knee};
}

std::pair<double, double> swing_ankle_target(
  const iceskate_native::Observation & obs, const BalanceParameters & p, double hip_y,
  double com_y, double com_vy)
{
  const double elapsed = obs.t - obs.t_exchange;
  const double up = smoothstep(elapsed / p.swing_time / p.lift_fraction);
  const double s = std::max(elapsed - p.glide_time, 0.0) / p.swing_time;  // the forward path
  const double down = smoothstep((s - p.descent_start) / (1.0 - p.descent_start));
  const double z = kAnkleHeight + p.clearance * up - (p.clearance + p.press) * down;
  const double land = com_y + p.step_length / 2.0 + p.placement_gain * (com_vy - p.speed);
  const double start = hip_y - kSwingStartBehind;
  return {start + (land - start) * smoothstep(s), z};
}

void balance_command(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const BalanceParameters & p, double yaw_stiffness, double yaw_damping, double head_start_y,
  iceskate_native::JointCommand & out)
{
  const auto & q = obs.q;
  const auto & v = obs.v;
  const auto state = obs.support();
  const iceskate_native::Mode & mode = kinematics.mode(obs.mode);
  const iceskate_native::CentreOfMass com = kinematics.centre_of_mass(state, q, v);
  const double phi3 = (mode.q1_active ? q[1] : 0.0) + q[2] + q[3];
  const double phi4 = phi3 + q[4];
  auto & K = out.stiffness;
  auto & B = out.damping;
  auto & R = out.reference;
  auto & effort = out.effort;
  K.setZero();
  B.setZero();
  R.setZero();
  effort.setZero();
  out.has_impedance = true;
  const auto pd = [&](int j, double stiffness, double damping, double reference) {
    K[j] = stiffness;
    B[j] = damping;
    R[j] = reference;
  };

  const double blend = p.blend > 0.0 ? smoothstep((obs.t - obs.t_exchange) / p.blend) : 1.0;
  pd(9, p.stiffness, 16.0, 0.0);
  pd(10, p.stiffness, 16.0, 0.0);
  pd(3, p.stiffness, 40.0, q[3] + blend * (p.stance_knee - q[3]));
  pd(2, p.ankle_stiffness, p.ankle_damping, q[2] + blend * (-p.stance_knee / 2.0 - q[2]));
  pd(4, p.stiffness, 80.0, p.trunk - phi3 - q[9] - q[10]);
  pd(8, yaw_stiffness, yaw_damping, 0.0);
  const double ramp = std::min(obs.t / 0.5, 1.0);
  double feedback = p.speed_gain * (p.speed * ramp - com.velocity[1]);
  if (p.pace_gain != 0.0) {  // the head's lag behind the pace point
    const double head_y = kinematics.frame_position(state, q, iceskate_native::Frame::kHeadTop)[1];
    feedback += p.pace_gain * (head_start_y + p.speed * obs.t - head_y);
  }
  if (p.feedback_limit > 0.0) {
    feedback = std::min(std::max(feedback, -p.feedback_limit), p.feedback_limit);
  }
  const double force = std::min(std::max(p.drive * ramp + feedback, -p.max_brake), p.max_force);
  for (int j : kSpeedJoints) {
    effort[j] += com.jacobian_y[j] * force;
  }
  if (p.com_stiffness != 0.0 || p.com_damping != 0.0) {
    const double ankle_y = kinematics.joint_position(state, q, kAnkle)[1];
    const double ankle_vy = kinematics.joint_velocity(state, q, v, kAnkle)[1];
    effort[kAnkle] += p.com_stiffness * (com.position[1] - ankle_y - p.com_offset)
                      + p.com_damping * (com.velocity[1] - ankle_vy);
  }
  const iceskate_native::Vector18 gravity = kinematics.gravity(state, q);
  for (int j : kGravityJoints) {
    effort[j] += gravity[j];
  }
  if (iceskate_native::swing_contact(mode) == iceskate_native::SwingContact::kAir) {
    const Eigen::Vector3d hip = kinematics.joint_position(state, q, kSwingHip);
    const auto [y, z] = swing_ankle_target(obs, p, hip[1], com.position[1], com.velocity[1]);
    const auto [phi5, phi6] = leg_ik(y - hip[1], z - hip[2], kThigh, kShank);
    pd(5, p.swing_stiffness, p.swing_damping, phi5 - phi4);
    pd(6, p.swing_stiffness, p.swing_damping, phi6 - phi5);
    effort[4] += p.swing_stiffness * (phi5 - phi4 - q[5]) - p.swing_damping * v[5];
  } else {
    const double knee =
      p.front_knee_step == 0.0
        ? kFrontKnee
        : std::min(std::max(kFrontKnee, q[6] - p.front_knee_step), q[6] + p.front_knee_step);
    pd(6, p.front_knee_stiffness, 20.0, knee);
    pd(5, p.front_hip_stiffness, 20.0, q[5]);  // held where it is at this instant
    if (obs.t_touchdown > obs.t_exchange) {
      const double r =
        p.push_ramp > 0.0
          ? std::min(std::max((obs.t - obs.t_touchdown) / p.push_ramp, 0.0), 1.0)
          : 1.0;
      K[2] *= 1.0 - r;
      effort[2] += p.push * r;
      R[3] = p.stance_knee + r * (p.toe_off_flex - p.stance_knee);
    }
  }
  if (!effort.allFinite() || !R.allFinite()) {
    throw GaitManagerError("balance command is not finite at t = " + std::to_string(obs.t));
  }
}

}  // namespace gait_manager
