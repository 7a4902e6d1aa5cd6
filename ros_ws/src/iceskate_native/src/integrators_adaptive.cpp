// The adaptive method of integrators.hpp: Dormand-Prince 5(4) with its FSAL stages and its
// continuous extension from Boost.Odeint (runge_kutta_dopri5 under controlled_runge_kutta),
// events located on that dense output. In a translation unit of its own: Odeint's headers are
// heavy and only this method needs them.
#include <algorithm>
#include <cmath>
#include <string>

// Odeint's Eigen support without eigen.hpp: its algebra dispatcher does not compile against
// Boost 1.90, and the stepper here names its algebra (vector_space_algebra) itself.
#include <boost/numeric/odeint/external/eigen/eigen_algebra.hpp>
#include <boost/numeric/odeint/external/eigen/eigen_resize.hpp>
#include <boost/numeric/odeint/stepper/controlled_runge_kutta.hpp>
#include <boost/numeric/odeint/stepper/runge_kutta_dopri5.hpp>

#include "iceskate_native/errors.hpp"
#include "iceskate_native/integrators.hpp"

namespace iceskate_native
{

namespace
{

namespace odeint = boost::numeric::odeint;

// A dynamic-size vector: a default-constructed stepper holds no uninitialised fixed-size
// storage for its copy constructor to read (GCC's -Wmaybe-uninitialized otherwise).
using OdeState = Eigen::VectorXd;
using Stepper = odeint::runge_kutta_dopri5<OdeState, double, OdeState, double,
                                           odeint::vector_space_algebra>;
using ErrorChecker = odeint::default_error_checker<double, odeint::vector_space_algebra,
                                                   odeint::default_operations>;
using StepAdjuster = odeint::default_step_adjuster<double, double>;
using Controlled = odeint::controlled_runge_kutta<Stepper, ErrorChecker, StepAdjuster>;

/// xdot = (v, qdd) of one mode under held inputs; keeps the dynamics of its last call (the
/// stepper's last stage of an accepted step is its end: FSAL).
struct Rate
{
  Rate(Dynamics & dynamics, const Contact & contact, const Inputs & inputs, int & evaluations)
  : dynamics(dynamics), contact(contact), inputs(inputs), evaluations(evaluations)
  {
  }

  void operator()(const OdeState & x, OdeState & xdot, double /* t */)
  {
    last = dynamics.evaluate(contact, x.head<kCoordinates>(), x.tail<kCoordinates>(), inputs);
    last_x = x;
    ++evaluations;
    xdot.resize(2 * kCoordinates);
    xdot << x.tail<kCoordinates>(), last.qdd;
  }

  Dynamics & dynamics;
  const Contact & contact;
  const Inputs & inputs;
  int & evaluations;
  OdeState last_x;  // where `last` was evaluated (empty: nowhere yet)
  DynamicsResult last;
};

}  // namespace

Segment integrate_adaptive(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs,
  const Tolerances & tolerances, double event_tolerance, const GuardSet & guards, double t0,
  const State & x0, double t_end, const DynamicsResult & start, double & step)
{
  const Tolerances & tol = tolerances;
  require_adaptive_settings(tol, event_tolerance, t0, t_end, "rk45");
  Segment segment;
  Rate rate{dynamics, contact, inputs, segment.evaluations};
  // Odeint's default control: error <= atol + rtol (|x| + h |xdot|) per entry, step bounded
  Controlled controlled(ErrorChecker(tol.atol, tol.rtol, 1.0, 1.0), StepAdjuster(tol.max_step));
  double t = t0;
  OdeState x = x0;
  OdeState xdot(2 * kCoordinates);
  xdot << x0.tail<kCoordinates>(), start.qdd;
  DynamicsResult r0 = start;
  Eigen::VectorXd g0 = guard_values(guards, contact, t, x, r0);
  double h = std::min(step > 0.0 ? step : tol.max_step, tol.max_step);
  const double end_gap = 1e-12 * std::max(1.0, std::abs(t_end));
  while (t_end - t > end_gap) {
    const bool last_step = h >= t_end - t;
    double h_try = last_step ? t_end - t : h;
    double t1 = t;
    OdeState x1(2 * kCoordinates);
    OdeState xdot1(2 * kCoordinates);
    if (controlled.try_step(std::ref(rate), x, xdot, t1, x1, xdot1, h_try) != odeint::success) {
      if (!(h_try > 1e-14 * std::max(1.0, std::abs(t)))) {
        throw NativeError("rk45: the step size fell below 1e-14 s at t = " + std::to_string(t)
                          + " s (the error control cannot be met)");
      }
      h = h_try;  // smaller
      continue;
    }
    if (last_step) {
      t1 = t_end;  // exactly, not t + (t_end - t)
    }
    segment.steps += 1;
    h = last_step ? std::max(h, h_try) : h_try;  // a step cut at t_end says little of the next
    step = h;
    if (rate.last_x.size() != x1.size() || rate.last_x != x1) {  // (FSAL: it is, normally)
      rate(x1, xdot1, t1);
    }
    DynamicsResult r1 = rate.last;
    const Eigen::VectorXd g1 = guard_values(guards, contact, t1, State(x1), r1);
    const Stepper & dopri = controlled.stepper();
    const double t_start = t;
    const OdeState x_start = x;
    const OdeState xdot_start = xdot;
    OdeState dense(2 * kCoordinates);
    const auto at = [&](double s, State & xs, DynamicsResult & rs) {
      if (s > 0.0) {
        dopri.calc_state(t_start + s, dense, x_start, xdot_start, t_start, x1, xdot1, t1);
        xs = dense;
      } else {
        xs = x_start;
      }
      rs = dynamics.evaluate(contact, xs.head<kCoordinates>(), xs.tail<kCoordinates>(), inputs);
      ++segment.evaluations;
    };
    if (first_crossing(guards, contact, event_tolerance, t, g0, g1, t1 - t, at, segment)) {
      return segment;
    }
    t = t1;
    x = x1;
    xdot = xdot1;
    r0 = std::move(r1);
    g0 = g1;
  }
  return segment.reached(t_end, x, std::move(r0));
}

}  // namespace iceskate_native
