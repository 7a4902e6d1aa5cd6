#include "gait_manager/heel.hpp"

#include <algorithm>

namespace gait_manager
{

namespace
{

constexpr int kSwingAnkle = 7;

/// theta_land(t) [rad]: a linear ramp from 0 at t_e to the landing pitch.
double landing_pitch(const iceskate_native::Observation & obs, const HeelParameters & params)
{
  if (params.ramp_time == 0.0) {
    return params.landing_pitch;
  }
  return params.landing_pitch
         * std::min(std::max((obs.t - obs.t_exchange) / params.ramp_time, 0.0), 1.0);
}

}  // namespace

iceskate_native::Vector18 heel_torque(
  const iceskate_native::Observation & obs, const iceskate_native::Mode & mode,
  const HeelParameters & params)
{
  iceskate_native::Vector18 tau = iceskate_native::Vector18::Zero();
  const auto swing = iceskate_native::swing_contact(mode);
  if (swing == iceskate_native::SwingContact::kSole) {
    return tau;
  }
  double theta = 0.0, rate = 0.0;  // swing-sole pitch theta_sf = q1 (if active) + ... + q7
  for (int i = mode.q1_active ? 1 : 2; i <= kSwingAnkle; ++i) {
    theta += obs.q[i];
    rate += obs.v[i];
  }
  if (swing == iceskate_native::SwingContact::kAir) {
    tau[kSwingAnkle] =
      params.stiffness * (landing_pitch(obs, params) - theta) - params.damping * rate;
  } else {
    tau[kSwingAnkle] = -params.contact_stiffness * theta - params.contact_damping * rate;
  }
  return tau;
}

}  // namespace gait_manager
