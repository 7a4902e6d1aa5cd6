#include "gait_manager/feedforward.hpp"

#include <algorithm>
#include <cmath>

#include "gait_manager/constants.hpp"

namespace gait_manager
{

namespace
{

using iceskate_native::SwingContact;
using iceskate_native::Vector18;

constexpr int kPivot = 1, kAnkle = 2, kKnee = 3, kSwingHip = 5, kSwingKnee = 6, kSwingAnkle = 7;

/// Half sine amplitude sin(pi dt / duration) on [0, duration], 0 elsewhere.
double pulse(double amplitude, double duration, double dt)
{
  if (0.0 <= dt && dt <= duration) {
    return amplitude * std::sin(kPi * dt / duration);
  }
  return 0.0;
}

}  // namespace

Vector18 feedforward_torque(
  const iceskate_native::Observation & obs, const iceskate_native::Mode & mode,
  const FeedforwardParameters & params)
{
  Vector18 tau = Vector18::Zero();
  const double dt = obs.t - obs.t_exchange;
  if (iceskate_native::swing_contact(mode) == SwingContact::kAir) {
    tau[kSwingHip] = pulse(params.hip_amplitude, params.hip_duration, dt);
    if (dt <= params.knee_duration) {
      tau[kSwingKnee] = -pulse(params.knee_amplitude, params.knee_duration, dt);
    } else {
      tau[kSwingKnee] = params.knee_stiffness * (params.knee_reference - obs.q[kSwingKnee])
                        - params.knee_damping * obs.v[kSwingKnee];
    }
  }
  if (mode.q1_active && obs.pivot == 0) {  // on the toe pivot
    tau[kAnkle] = params.ankle_push;
    tau[kKnee] = -params.knee_push;
    if (params.joint1_torque) {
      tau[kPivot] = -params.pivot_push;
    }
  }
  return tau;
}

double desired_heel_force(
  const iceskate_native::Observation & obs, const iceskate_native::Mode & mode,
  const WeightTransferParameters & params, double total_mass)
{
  if (iceskate_native::swing_contact(mode) == SwingContact::kAir
      || !std::isfinite(obs.t_touchdown)) {
    return 0.0;
  }
  const double weight = total_mass * kGravity;
  if (obs.step_index == 0 && obs.t_touchdown <= obs.t_exchange) {  // down since the start
    if (params.start_ramp == 0.0) {
      return params.start_share * weight;
    }
    return params.start_share * weight
           * std::max(0.0, 1.0 - (obs.t - obs.t_exchange) / params.start_ramp);
  }
  const double final_force = params.share * weight;
  if (params.ramp_time == 0.0) {
    return final_force;
  }
  return final_force
         * std::min(std::max((obs.t - obs.t_touchdown) / params.ramp_time, 0.0), 1.0);
}

double capture_split_force(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const WeightTransferParameters & params)
{
  if (iceskate_native::swing_contact(kinematics.mode(obs.mode)) == SwingContact::kAir) {
    return 0.0;
  }
  const auto state = obs.support();
  const iceskate_native::CentreOfMass com = kinematics.centre_of_mass(state, obs.q, obs.v);
  const double rear_toe =
    kinematics.frame_position(state, obs.q, iceskate_native::Frame::kSupportToe)[1];
  const double front_heel =
    kinematics.frame_position(state, obs.q, iceskate_native::Frame::kSwingHeel)[1];
  if (front_heel
      <= kinematics.frame_position(state, obs.q, iceskate_native::Frame::kSupportHeel)[1]) {
    return 0.0;  // the swing foot is down behind the support: no load goes onto it
  }
  const double y_x = com.position[1] + params.capture_gain * com.velocity[1]
                                         * std::sqrt(std::max(com.position[2], 0.0) / kGravity);
  const double share = std::min(
    std::max((y_x - rear_toe) / std::max(front_heel - rear_toe, 0.02), 0.0), params.share);
  const double since = obs.t - obs.t_touchdown;
  const double floor =
    params.share_min * (params.ramp_time > 0.0 ? std::min(since / params.ramp_time, 1.0) : 1.0);
  double fraction = std::max(share, floor);
  if (iceskate_native::swing_contact(kinematics.mode(obs.mode)) == SwingContact::kHeel) {
    double bound = params.heel_share;  // only the front heel touches
    if (params.heel_time > 0.0 && since > params.heel_time) {
      const double rise =
        params.ramp_time > 0.0 ? std::min((since - params.heel_time) / params.ramp_time, 1.0) : 1.0;
      bound += rise * std::max(params.share - params.heel_share, 0.0);
    }
    fraction = std::min(fraction, bound);
  }
  return fraction * kinematics.total_mass() * kGravity;
}

Vector18 weight_transfer_torque(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const WeightTransferParameters & params)
{
  const iceskate_native::Mode & mode = kinematics.mode(obs.mode);
  const double force = params.rule == WeightRule::kCom && obs.t_touchdown > obs.t_exchange
                         ? capture_split_force(obs, kinematics, params)
                         : desired_heel_force(obs, mode, params, kinematics.total_mass());
  Vector18 tau = Vector18::Zero();
  if (force == 0.0) {
    return tau;
  }
  tau -= force * kinematics.swing_heel_z_row(obs.support(), obs.q);
  if (params.rule == WeightRule::kRamp
      && iceskate_native::swing_contact(mode) == SwingContact::kSole
      && params.moment_arm != 0.0) {
    tau.segment<7>(kPivot).array() -= params.moment_arm * force;  // q1..q7: j_r
  }
  tau[0] = 0.0;
  if (!(mode.q1_active && params.joint1_torque)) {
    tau[kPivot] = 0.0;
  }
  return tau;
}

}  // namespace gait_manager
