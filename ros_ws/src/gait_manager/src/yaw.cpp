#include "gait_manager/yaw.hpp"

#include <cmath>

namespace gait_manager
{

iceskate_native::Vector18 yaw_torque(
  const iceskate_native::Observation & obs, const YawParameters & params)
{
  constexpr int kYawJoint = 8;
  iceskate_native::Vector18 tau = iceskate_native::Vector18::Zero();
  const double sign = obs.side == 0 ? 1.0 : -1.0;
  tau[kYawJoint] =
    sign * params.amplitude * std::sin(phase(params.phase, obs.t, obs.t_exchange, params.period));
  return tau;
}

}  // namespace gait_manager
