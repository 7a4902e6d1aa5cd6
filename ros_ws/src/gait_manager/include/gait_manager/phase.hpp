// The phase Phi of the paper's eq. (10) (docs/model.md §11.8), used by the torso-yaw input and
// the arm assist; PhaseReading is generated from PHASE_READINGS (gait_manager/parameters.py).
#pragma once

#include "gait_manager/parameters.hpp"

namespace gait_manager
{

/// Phi [rad] at t [s] after the exchange at t_exchange [s], period T [s].
double phase(PhaseReading reading, double t, double t_exchange, double period);

}  // namespace gait_manager
