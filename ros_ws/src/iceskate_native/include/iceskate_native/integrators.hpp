// Integration of one mode with event location (docs/model.md §6.4, §8.1): the state
// x = [q (18), v (18)] advances with the inputs held, and stops at the first guard whose value
// crosses zero from below, located to the event tolerance by TOMS 748 (Boost.Math): for the
// fixed-step methods by re-taking the step with a shorter size, for the adaptive Dormand-Prince
// 5(4) pair (Boost.Odeint's runge_kutta_dopri5 under its step-size control,
// integrators_adaptive.cpp) and the Rosenbrock-W method ROS34PW2 (integrators_rosenbrock.cpp) on
// the step's dense output. Tested against the test oracle's
// Integrator.integrate_segment (tests/oracle/integrators.py).
#pragma once

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "iceskate_native/dynamics.hpp"
#include "iceskate_native/guards.hpp"

namespace iceskate_native
{

using State = Eigen::Matrix<double, 2 * kCoordinates, 1>;

/// The methods: fixed-step semi-implicit (symplectic) Euler, implicit Euler (semi-implicit
/// Euler with the damping taken implicitly), classic RK4; adaptive Dormand-Prince 5(4) and the
/// linearly implicit Rosenbrock-W method ROS34PW2 (order 3(2), L-stable).
enum class Method
{
  kSymplecticEuler,
  kImplicitEuler,
  kRk4,
  kRk45,
  kRos34pw2
};

/// The method called `name` (symplectic_euler, implicit_euler, rk4, rk45, ros34pw2);
/// std::invalid_argument otherwise.
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

  /// This segment as one that reached t_end at `at` (dynamics `there`) without an event.
  Segment & reached(double t_end, const State & at, DynamicsResult there)
  {
    t = t_end;
    x = at;
    result = std::move(there);
    return *this;
  }
};

/// The error control of an adaptive method: per state entry, the error estimate must stay
/// below atol + rtol (|x| + h |xdot|); steps of at most max_step [s].
struct Tolerances
{
  double rtol = 1e-8;
  double atol = 1e-10;
  double max_step = 1e-3;
};

/// std::invalid_argument unless an adaptive segment's tolerances, event tolerance and largest
/// step are > 0 and its times finite (`method` names it in the message).
void require_adaptive_settings(const Tolerances & tolerances, double event_tolerance, double t0,
                               double t_end, const char * method);

/// Advance from (t0, x0), whose dynamics are `start`, to t_end or the first guard crossing.
/// `method` is a fixed-step one.
Segment integrate_fixed(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs, Method method,
  double step, double event_tolerance, const GuardSet & guards, double t0, const State & x0,
  double t_end, const DynamicsResult & start);

/// The same with Dormand-Prince 5(4) under step-size control, events located on the dense
/// output. `step` holds the step size to try first and, after the call, the last one accepted
/// [s] (a run keeps it from segment to segment). NativeError if the step size underflows.
Segment integrate_adaptive(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs,
  const Tolerances & tolerances, double event_tolerance, const GuardSet & guards, double t0,
  const State & x0, double t_end, const DynamicsResult & start, double & step);

/// The same with ROS34PW2 under step-size control on its embedded estimate
/// (integrators_rosenbrock.cpp): each stage one eq. (7) evaluation and one solve with the step's
/// matrix (the held stiffness and damping, a soft stop's too from a step that would cross it),
/// events located on its dense output of order 3. `step` as in integrate_adaptive.
Segment integrate_rosenbrock(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs,
  const Tolerances & tolerances, double event_tolerance, const GuardSet & guards, double t0,
  const State & x0, double t_end, const DynamicsResult & start, double & step);

/// The state and its dynamics at offset s [s] into a step (at(s, x, result)).
using StateAt = std::function<void(double, State &, DynamicsResult &)>;

/// Whether a guard crossed from g0 (at t) to g1 (at t + h); if so, the earliest crossing is
/// located on `at` and written into segment (t, x, result, fired).
bool first_crossing(
  const GuardSet & guards, const Contact & contact, double event_tolerance, double t,
  const Eigen::VectorXd & g0, const Eigen::VectorXd & g1, double h, const StateAt & at,
  Segment & segment);

/// The guards' values at (t, x) with `result` (rested ones -1).
Eigen::VectorXd guard_values(
  const GuardSet & guards, const Contact & contact, double t, const State & x,
  const DynamicsResult & result);

}  // namespace iceskate_native
