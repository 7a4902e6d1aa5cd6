// Feed-forward leg torques (docs/model.md §11.4): swing hip and knee pulses after the exchange
// and push-off on the toe pivot; and weight transfer (§11.5): tau_wt = -J_c^T f_des -
// j_r^T tau_n,des, a desired vertical force on the swing heel, ramped after the heel strike
// ('ramp' rule) or split by the capture point ('com' rule). The counterpart of
// gait_manager/feedforward.py.
#pragma once

#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"

namespace gait_manager
{

/// FeedforwardParameters (gait_manager/feedforward.py, the one schema; units there).
struct FeedforwardParameters
{
  double hip_amplitude = 0.0;   ///< A5 [N m]
  double hip_duration = 0.0;    ///< D5 [s]
  double knee_amplitude = 0.0;  ///< A6 [N m]
  double knee_duration = 0.0;   ///< D6 [s]
  double knee_stiffness = 0.0;  ///< K6 [N m/rad]
  double knee_reference = 0.0;  ///< q6_ref [rad]
  double knee_damping = 0.0;    ///< B6 [N m s/rad]
  double ankle_push = 0.0;      ///< A2 [N m]
  double knee_push = 0.0;       ///< A3 [N m]
  double pivot_push = 0.0;      ///< A1 [N m]
  bool joint1_torque = false;
};

/// The weight-transfer rules: a time ramp to share, or the static split by the capture point.
enum class WeightRule
{
  kRamp,
  kCom
};

/// WeightTransferParameters (gait_manager/feedforward.py, the one schema; units there).
struct WeightTransferParameters
{
  double share = 0.0;        ///< of m g
  double ramp_time = 0.0;    ///< [s]
  double moment_arm = 0.0;   ///< [m]
  bool joint1_torque = false;
  double start_share = 0.0;  ///< of m g
  double start_ramp = 0.0;   ///< [s]
  WeightRule rule = WeightRule::kRamp;
  double capture_gain = 0.0;
  double share_min = 0.0;    ///< of m g
  double heel_share = 2.0;   ///< of m g
};

/// The feed-forward torques [N m] on joints 1, 2, 3 (push-off), 5, 6 (swing).
iceskate_native::Vector18 feedforward_torque(
  const iceskate_native::Observation & obs, const iceskate_native::Mode & mode,
  const FeedforwardParameters & params);

/// f_des [N] of the 'ramp' rule and of the starting double support (0 in the air).
double desired_heel_force(
  const iceskate_native::Observation & obs, const iceskate_native::Mode & mode,
  const WeightTransferParameters & params, double total_mass);

/// f_des [N] of the 'com' rule (0 in the air).
double capture_split_force(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const WeightTransferParameters & params);

/// tau_wt [N m] (zero before touchdown).
iceskate_native::Vector18 weight_transfer_torque(
  const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
  const WeightTransferParameters & params);

}  // namespace gait_manager
