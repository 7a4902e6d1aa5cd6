#include "iceskate_native/integrators.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include <boost/math/tools/toms748_solve.hpp>

#include "iceskate_native/errors.hpp"

namespace iceskate_native
{

namespace
{

using Velocity = Eigen::Matrix<double, kCoordinates, 1>;

// One step of size h from (t, x) whose accelerations are qdd0; `extra` counts the additional
// dynamics evaluations the step made.
State take_step(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs, Method method,
  const State & x, const Vector18 & qdd0, double h, int & extra)
{
  const Vector18 q = x.head<kCoordinates>();
  const Vector18 v = x.tail<kCoordinates>();
  if (method != Method::kRk4) {  // the Euler methods: v first, then q with the new v
    const bool implicit = method == Method::kImplicitEuler;
    const Vector18 v1 =
      v + h * (implicit ? dynamics.implicit_acceleration(contact, q, v, inputs, h) : qdd0);
    extra += implicit ? 1 : 0;
    State out;
    out << q + h * v1, v1;
    return out;
  }
  const auto rate = [&](const State & y) {
    State f;
    f << y.tail<kCoordinates>(),
      dynamics.evaluate(contact, y.head<kCoordinates>(), y.tail<kCoordinates>(), inputs).qdd;
    return f;
  };
  State k1;
  k1 << v, qdd0;
  const State k2 = rate(x + 0.5 * h * k1);
  const State k3 = rate(x + 0.5 * h * k2);
  const State k4 = rate(x + h * k3);
  extra += 3;
  return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
}

}  // namespace

bool first_crossing(
  const GuardSet & guards, const Contact & contact, double event_tolerance, double t,
  const Eigen::VectorXd & g0, const Eigen::VectorXd & g1, double h, const StateAt & at,
  Segment & segment)
{
  const double margin = guards.margin;
  double best = std::numeric_limits<double>::infinity();
  for (Eigen::Index i = 0; i < g1.size(); ++i) {
    if (!(g0[i] <= margin && g1[i] > margin)) {
      continue;
    }
    // phi(s): guard i minus the margin at offset s from t
    State xs;
    DynamicsResult rs;
    const auto phi = [&](double s) {
      at(s, xs, rs);
      return guard_values(guards, contact, t + s, xs, rs)[i] - margin;
    };
    const double f0 = g0[i] - margin;
    double s = 0.0;
    if (f0 < 0.0) {
      std::uintmax_t iterations = 100;
      const auto close = [event_tolerance](double a, double b) {
        return std::abs(b - a) <= event_tolerance;
      };
      const auto bracket =
        boost::math::tools::toms748_solve(phi, 0.0, h, f0, g1[i] - margin, close, iterations);
      s = bracket.second;  // the due side of the final bracket
    }
    double value = phi(s);
    double nudge = event_tolerance;
    while (value <= 0.0 && s < h) {  // move onto the due side of the zero
      s = std::min(h, s + nudge);
      nudge *= 2.0;
      value = phi(s);
    }
    if (s < best) {
      best = s;
      segment.t = t + s;
      segment.x = xs;
      segment.result = rs;
      segment.fired = static_cast<int>(i);
    }
  }
  return segment.fired >= 0;
}

void require_adaptive_settings(const Tolerances & tol, double event_tolerance, double t0,
                               double t_end, const char * method)
{
  if (!(tol.rtol > 0.0) || !(tol.atol > 0.0) || !(tol.max_step > 0.0) || !(event_tolerance > 0.0)
      || !std::isfinite(t0) || !std::isfinite(t_end))
  {
    throw std::invalid_argument(std::string("a ") + method + " segment needs rtol, atol, "
                                "max_step and event_tolerance > 0 and finite times");
  }
}

Method method_named(const std::string & name)
{
  if (name == "symplectic_euler") {
    return Method::kSymplecticEuler;
  }
  if (name == "implicit_euler") {
    return Method::kImplicitEuler;
  }
  if (name == "rk4") {
    return Method::kRk4;
  }
  if (name == "rk45") {
    return Method::kRk45;
  }
  if (name == "ros34pw2") {
    return Method::kRos34pw2;
  }
  throw std::invalid_argument(
    "no native method '" + name + "' (symplectic_euler, implicit_euler, rk4, rk45, ros34pw2)");
}

Eigen::VectorXd guard_values(
  const GuardSet & guards, const Contact & contact, double t, const State & x,
  const DynamicsResult & result)
{
  const std::size_t count = guards.guards.size();
  Eigen::VectorXd values(static_cast<Eigen::Index>(count));
  const Vector18 q = x.head<kCoordinates>();
  const Vector18 v = x.tail<kCoordinates>();
  for (std::size_t i = 0; i < count; ++i) {
    const bool rested = i < guards.rested_until.size() && guards.rested_until[i] > t;
    values[static_cast<Eigen::Index>(i)] =
      rested ? -1.0
             : guard_value(guards.guards[i], contact, q, v, result, guards.friction,
                           guards.constants);
  }
  return values;
}

Segment integrate_fixed(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs, Method method,
  double step, double event_tolerance, const GuardSet & guards, double t0, const State & x0,
  double t_end, const DynamicsResult & start)
{
  if (!(step > 0.0) || !(event_tolerance > 0.0) || !std::isfinite(t0) || !std::isfinite(t_end)) {
    throw std::invalid_argument("a segment needs step > 0, event_tolerance > 0 and finite times");
  }
  if (method == Method::kRk45 || method == Method::kRos34pw2) {
    throw std::invalid_argument("rk45 and ros34pw2 are adaptive: they have no fixed-step segment");
  }
  Segment segment;
  double t = t0;
  State x = x0;
  DynamicsResult r0 = start;
  Eigen::VectorXd g0 = guard_values(guards, contact, t, x, r0);
  while (t_end - t > 1e-12 * std::max(1.0, std::abs(t_end))) {
    const double h = std::min(step, t_end - t);
    int extra = 0;
    const State x1 = take_step(dynamics, contact, inputs, method, x, r0.qdd, h, extra);
    DynamicsResult r1 = dynamics.evaluate(
      contact, x1.head<kCoordinates>(), x1.tail<kCoordinates>(), inputs);
    segment.evaluations += extra + 1;
    segment.steps += 1;
    const Eigen::VectorXd g1 = guard_values(guards, contact, t + h, x1, r1);

    const auto at = [&](double s, State & xs, DynamicsResult & rs) {
      int more = 0;
      xs = s > 0.0 ? take_step(dynamics, contact, inputs, method, x, r0.qdd, s, more) : x;
      rs = dynamics.evaluate(contact, xs.head<kCoordinates>(), xs.tail<kCoordinates>(), inputs);
      segment.evaluations += more + 1;
    };
    if (first_crossing(guards, contact, event_tolerance, t, g0, g1, h, at, segment)) {
      return segment;
    }
    t += h;
    x = x1;
    r0 = std::move(r1);
    g0 = g1;
  }
  return segment.reached(t_end, x, std::move(r0));
}

}  // namespace iceskate_native
