// Fixed-step integration of one mode with event location (docs/model.md §6.4, §8.1): the state
// x = [q (18), v (18)] advances with the inputs held, and stops at the first guard whose value
// crosses zero from below, located by re-taking the step with a shorter size until the event
// time is within the tolerance (TOMS 748 from Boost.Math). The native counterpart of the fixed-
// step path of iceskate_sim.integrators.Integrator.integrate_segment.
#pragma once

#include <utility>
#include <vector>

#include "iceskate_native/dynamics.hpp"
#include "iceskate_native/guards.hpp"

namespace iceskate_native
{

using State = Eigen::Matrix<double, 2 * kCoordinates, 1>;

/// The fixed-step methods: semi-implicit (symplectic) Euler, implicit Euler (semi-implicit
/// Euler with the damping taken implicitly), classic RK4.
enum class Method
{
  kSymplecticEuler,
  kImplicitEuler,
  kRk4
};

/// The method called `name` (symplectic_euler, implicit_euler, rk4); std::invalid_argument
/// otherwise.
Method method_named(const std::string & name);

/// What the guards need besides the state: the mode's guards, friction, constants, the
/// guards at rest until a time (a rested guard reads -1, not due), the due margin.
struct GuardSet
{
  std::vector<Guard> guards;
  std::vector<double> rested_until;  ///< per guard [s]; -inf: not rested
  Friction friction;
  GuardConstants constants;
  double margin = 1e-9;  ///< a guard at most this positive is not due
};

/// The outcome of a segment: time reached, state, dynamics there, the guard that fired (index
/// into GuardSet::guards, -1: the end time was reached), steps and dynamics evaluations.
struct Segment
{
  double t = 0.0;
  State x = State::Zero();
  DynamicsResult result;
  int fired = -1;
  int steps = 0;
  int evaluations = 0;
};

/// Advance from (t0, x0), whose dynamics are `start`, to t_end or the first guard crossing.
Segment integrate_fixed(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs, Method method,
  double step, double event_tolerance, const GuardSet & guards, double t0, const State & x0,
  double t_end, const DynamicsResult & start);

/// The guards' values at (t, x) with `result` (rested ones -1).
Eigen::VectorXd guard_values(
  const GuardSet & guards, const Contact & contact, double t, const State & x,
  const DynamicsResult & result);

}  // namespace iceskate_native
