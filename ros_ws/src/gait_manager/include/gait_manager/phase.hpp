// The phase Phi of the paper's eq. (10) (docs/model.md §11.8), shared by the torso-yaw input and
// the arm assist (gait_manager/_params.py).
#pragma once

namespace gait_manager
{

/// How Phi is read: 'A' 2 (t - t_e)/T (literal), 'B' 2 pi (t - t_e)/T, 'B_clipped' reading B
/// clipped to [0, pi].
enum class PhaseReading
{
  kA,
  kB,
  kBClipped
};

/// Phi [rad] at t [s] after the exchange at t_exchange [s], period T [s].
double phase(PhaseReading reading, double t, double t_exchange, double period);

}  // namespace gait_manager
