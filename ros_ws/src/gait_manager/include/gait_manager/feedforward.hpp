// Feed-forward leg torques (docs/model.md §11.4): swing hip and knee pulses after the exchange
// and push-off on the toe pivot; and weight transfer (§11.5): tau_wt = -J_c^T f_des -
// j_r^T tau_n,des, a desired vertical force on the swing heel, ramped after the heel strike
// ('ramp' rule) or split by the capture point ('com' rule). Their parameters:
// FeedforwardParameters, WeightTransferParameters (gait_manager/parameters.hpp, generated).
#pragma once

#include "gait_manager/parameters.hpp"
#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"

namespace gait_manager
{

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
