// The moving stance (docs/model.md §11.2): after the support exchange at t_e the stance moves
// dy1 forward and dz1 down over T1, then, once the swing heel has struck at t_touchdown, a
// further dy2 forward over T2 (smoothstep ramps). Visual lifting shifts its head target by it,
// the gait manager's posture reference moves the pelvis with it: the counterpart of
// iceskate_sim.model.stance, header-only so that both controller packages use it without linking.
#pragma once

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

#include "iceskate_native/controller.hpp"

namespace iceskate_native
{

/// 3x^2 - 2x^3 on [0, 1], clamped outside.
inline double smoothstep(double x)
{
  x = std::min(std::max(x, 0.0), 1.0);
  return x * x * (3.0 - 2.0 * x);
}

/// A smoothstep from 0 to 1 over `duration` [s] after dt = 0 (a step if 0 s).
inline double ramp(double dt, double duration)
{
  if (duration == 0.0) {
    return dt >= 0.0 ? 1.0 : 0.0;
  }
  return smoothstep(dt / duration);
}

/// The shift schedule: dy1 [m] forward and dz1 [m] down over t1 [s] after t_e, then dy2 [m]
/// forward over t2 [s] after the heel strike.
struct StanceSchedule
{
  double dy1 = 0.0;
  double dz1 = 0.0;
  double t1 = 0.0;
  double dy2 = 0.0;
  double t2 = 0.0;

  /// (dy, dz) [m] of the stance at `obs` (dz < 0 is down).
  Eigen::Vector2d shift(const Observation & obs) const
  {
    const double s1 = ramp(obs.t - obs.t_exchange, t1);
    double dy = dy1 * s1;
    const double dz = -dz1 * s1;
    if (std::isfinite(obs.t_touchdown)) {
      dy += dy2 * ramp(obs.t - obs.t_touchdown, t2);
    }
    return {dy, dz};
  }
};

/// The schedule of a law's parameters with the fields shift_y1, shift_z1, shift_time1,
/// shift_y2 and shift_time2.
template <class Parameters>
StanceSchedule stance_schedule(const Parameters & p)
{
  return {p.shift_y1, p.shift_z1, p.shift_time1, p.shift_y2, p.shift_time2};
}

}  // namespace iceskate_native
