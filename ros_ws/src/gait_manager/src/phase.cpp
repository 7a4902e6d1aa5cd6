#include "gait_manager/phase.hpp"

#include <algorithm>
#include <cmath>

#include "gait_manager/constants.hpp"

namespace gait_manager
{

double phase(PhaseReading reading, double t, double t_exchange, double period)
{
  const double dt = t - t_exchange;
  if (reading == PhaseReading::kA) {
    return 2.0 * dt / period;
  }
  const double phi = 2.0 * kPi * dt / period;
  if (reading == PhaseReading::kBClipped) {
    return std::min(std::max(phi, 0.0), kPi);
  }
  return phi;
}

}  // namespace gait_manager
