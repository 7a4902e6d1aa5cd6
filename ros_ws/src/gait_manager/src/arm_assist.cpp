#include "gait_manager/arm_assist.hpp"

#include <cmath>

#include "iceskate_native/stance.hpp"

namespace gait_manager
{

namespace
{

constexpr int kRightShoulder = 11, kLeftShoulder = 14;
constexpr int kElbowsAndWrists[] = {12, 13, 15, 16};

}  // namespace

iceskate_native::Vector18 arm_assist_torque(
  const iceskate_native::Observation & obs, const ArmAssistParameters & params)
{
  iceskate_native::Vector18 tau = iceskate_native::Vector18::Zero();
  if (obs.step_index >= params.off_from_step_index) {
    const double elapsed = obs.t - obs.t_exchange;
    if (obs.step_index == params.off_from_step_index && elapsed < params.release_time) {
      const double fade = 1.0 - iceskate_native::smoothstep(elapsed / params.release_time);
      for (int j : {kRightShoulder, kLeftShoulder}) {
        tau[j] = -params.release_damping * fade * obs.v[j];
      }
    }
    return tau;
  }
  const double sign = obs.side == 0 ? 1.0 : -1.0;
  const double phi = phase(params.phase, obs.t, obs.t_exchange, params.period);
  tau[kRightShoulder] = sign * params.amplitude * std::sin(phi);
  tau[kLeftShoulder] = -tau[kRightShoulder];
  for (int j : kElbowsAndWrists) {
    tau[j] = -params.stiffness * obs.q[j] - params.damping * obs.v[j];
  }
  return tau;
}

}  // namespace gait_manager
