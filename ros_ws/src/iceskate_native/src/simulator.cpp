#include "iceskate_native/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include <Eigen/LU>

namespace iceskate_native
{

namespace
{

const char * name_of(Guard guard) { return kGuardNames[static_cast<std::size_t>(guard)]; }

std::string format(const char * pattern, double a, double b)
{
  char text[160];
  std::snprintf(text, sizeof(text), pattern, a, b);
  return text;
}

}  // namespace

struct HybridSimulator::Ended
{
  RunEnd reason;
  HybridState state;
};

HybridSimulator::HybridSimulator(
  Dynamics & dynamics, SimulatorSettings settings, HybridState initial)
: dynamics_(dynamics), settings_(std::move(settings)), initial_(std::move(initial))
{
  const SimulatorSettings & s = settings_;
  if (!(s.step > 0.0) || !(s.control_period > 0.0) || !(s.event_tolerance > 0.0)) {
    throw std::invalid_argument("step, control_period and event_tolerance must be > 0 s");
  }
  const double ratio = s.control_period / s.step;
  if (s.method != Method::kRk45 && s.method != Method::kRos34pw2
      && (std::abs(ratio - std::round(ratio)) > 1e-9 * ratio || std::round(ratio) < 1.0))
  {
    throw std::invalid_argument("control_period must be an integer multiple of the step");
  }
  if (!(s.rtol > 0.0) || !(s.atol > 0.0) || !std::isfinite(s.rtol) || !std::isfinite(s.atol)) {
    throw std::invalid_argument("rtol and atol must be finite and > 0");
  }
  if (s.max_instant_transitions < 1) {
    throw std::invalid_argument("max_instant_transitions must be >= 1");
  }
  for (double value : {s.margin, s.residual_bound, s.fall_height, s.max_speed, s.zeno_window,
                       s.chatter_dwell}) {
    if (!std::isfinite(value)) {
      throw std::invalid_argument("the simulator's bounds and times must be finite");
    }
  }
  dynamics_.mode(initial_.contact.mode);  // std::invalid_argument for an unknown mode
  reset();
}

void HybridSimulator::reset()
{
  state_ = initial_;
  const Mode & mode = dynamics_.mode(state_.contact.mode);
  if (mode.multiplier_index(Constraint::kHeelY) >= 0) {  // a pinned heel is held where it is
    state_.contact.heel_anchor_y = dynamics_.frame_position(state_.contact, state_.q,
                                                            "swing_heel")[1];
  }
  events_.clear();
  stats_ = RunStatistics{};
  ended_ = RunEnd::kNone;
  inputs_ = Inputs{};
  suppressed_.clear();
  instant_time_ = std::numeric_limits<double>::quiet_NaN();
  instant_modes_.clear();
  adaptive_step_ = 0.0;
  result_ = evaluate(state_);
  start_state_ = state_;
  start_result_ = result_;
  try {
    settle();
  } catch (const Ended & end) {
    ended_ = end.reason;
    state_ = end.state;
  }
}

void HybridSimulator::set_state(const HybridState & s)
{
  dynamics_.mode(s.contact.mode);  // std::invalid_argument for an unknown mode
  state_ = s;
  ended_ = RunEnd::kNone;
  result_ = evaluate(state_);
}

DynamicsResult HybridSimulator::evaluate(const HybridState & s)
{
  return dynamics_.evaluate(s.contact, s.q, s.v, inputs_);
}

GuardSet HybridSimulator::guard_set(const HybridState & s) const
{
  GuardSet set;
  set.guards = settings_.guards[static_cast<std::size_t>(s.contact.mode - 1)];
  set.friction = settings_.friction;
  set.constants = settings_.constants;
  set.margin = settings_.margin;
  if (!suppressed_.empty()) {
    for (Guard guard : set.guards) {
      const auto it = suppressed_.find(guard);
      set.rested_until.push_back(
        it == suppressed_.end() ? -std::numeric_limits<double>::infinity() : it->second);
    }
  }
  return set;
}

void HybridSimulator::advance(const Inputs & inputs)
{
  if (ended_ != RunEnd::kNone) {
    throw std::invalid_argument("the run has ended; no further period can be simulated");
  }
  inputs_ = inputs;
  start_state_ = state_;
  result_ = start_result_ = evaluate(state_);
  const double t_end = state_.t + settings_.control_period;
  double instant = state_.t;
  int at_instant = 0;
  const HybridState period_start = state_;
  const std::map<Guard, double> rested_at_start = suppressed_;
  bool integrating = false;  // past the transitions due at the period's start
  try {
    settle();  // a guard the new input makes due fires at the period start
    start_state_ = state_;
    start_result_ = result_;
    integrating = true;
    while (t_end - state_.t > 1e-12) {
      const GuardSet guards = guard_set(state_);
      State x0;
      x0 << state_.q, state_.v;
      const Segment seg =
        settings_.method == Method::kRk45
          ? integrate_adaptive(
              dynamics_, state_.contact, inputs_,
              {settings_.rtol, settings_.atol, settings_.step}, settings_.event_tolerance,
              guards, state_.t, x0, t_end, result_, adaptive_step_)
        : settings_.method == Method::kRos34pw2
          ? integrate_rosenbrock(
              dynamics_, state_.contact, inputs_,
              {settings_.rtol, settings_.atol, settings_.step}, settings_.event_tolerance,
              guards, state_.t, x0, t_end, result_, adaptive_step_)
          : integrate_fixed(
              dynamics_, state_.contact, inputs_, settings_.method, settings_.step,
              settings_.event_tolerance, guards, state_.t, x0, t_end, result_);
      stats_.steps += seg.steps;
      stats_.evaluations += seg.evaluations;
      if (!seg.x.allFinite()) {
        HybridState at = state_;
        at.t = seg.t;
        diverged("non-finite state", at);
      }
      state_.t = seg.t;
      state_.q = seg.x.head<kCoordinates>();
      state_.v = seg.x.tail<kCoordinates>();
      result_ = seg.result;
      if (seg.fired >= 0) {
        const Guard guard = guards.guards[static_cast<std::size_t>(seg.fired)];
        if (seg.t - instant > settings_.zeno_window) {
          instant = seg.t;
          at_instant = 0;
        }
        if (++at_instant > settings_.max_instant_transitions) {
          // a Zeno burst (events ever closer, e.g. stick <-> slip at a heel at rest): rest the
          // firing guard, the last resort
          rest(guard);
          instant = seg.t;
          at_instant = 0;
          continue;
        }
        transition(guard);
        settle();
      }
    }
    Eigen::VectorXd residual;
    const bool known =
      settings_.projection && !dynamics_.mode(state_.contact.mode).constraints.empty()
      && project(residual);
    check_health(known ? &residual : nullptr);
  } catch (const Ended & end) {
    check_speed(end.state);  // a blow-up is not a physical end
    if (integrating) {
      confirm_end(period_start, rested_at_start, inputs, end.reason, end.state);
    }
    ended_ = end.reason;
    state_ = end.state;
  }
  stats_.control_periods += 1;
}

void HybridSimulator::confirm_end(
  const HybridState & start, const std::map<Guard, double> & rested, const Inputs & inputs,
  RunEnd end, const HybridState & at)
{
  SimulatorSettings check = settings_;
  check.method = Method::kRk45;
  check.rtol = std::min(settings_.rtol, 1.0e-8);
  check.atol = std::min(settings_.atol, 1.0e-10);
  check.step = settings_.control_period;
  if (settings_.method == check.method && settings_.rtol <= 1.0e-8
      && settings_.atol <= 1.0e-10)
  {
    return;  // as accurate as the check already
  }
  try {  // the period again from its start as it was: its state, rested guards, no instant yet
    HybridSimulator again(dynamics_, check, start);
    again.set_state(start);
    again.suppressed_ = rested;
    again.events_.clear();
    again.instant_time_ = std::numeric_limits<double>::quiet_NaN();
    again.instant_modes_.clear();
    const int periods =
      std::max(1, static_cast<int>(std::ceil(kEndCheckTime / settings_.control_period - 1e-9)));
    for (int k = 0; k < periods && again.ended() == RunEnd::kNone; ++k) {
      again.advance(inputs);
    }
    if (again.ended() != RunEnd::kNone) {
      return;
    }
  } catch (const std::exception &) {
    return;  // the check failed (diverged, chattered): the end stands as the method found it
  }
  static const char * const kEnds[] = {"none", "flight", "toe-first touchdown", "fall"};
  const char * advice = "take a smaller integrator.rtol and atol";
  if (settings_.method == Method::kImplicitEuler) {
    advice = "take a smaller integrator.step, or the ros34pw2 method";
  } else if (settings_.method == Method::kRk4 || settings_.method == Method::kSymplecticEuler) {
    advice = "take a smaller integrator.step, or an implicit method (implicit_euler, ros34pw2)";
  }
  const bool fixed = settings_.method != Method::kRk45 && settings_.method != Method::kRos34pw2;
  char what[320];
  std::snprintf(
    what, sizeof(what),
    "the integration ended the run in a %s that rk45 at rtol 1e-8 does not reach from the "
    "period's start under the same command: %s; %s",
    kEnds[static_cast<int>(end)],
    fixed ? "its step is too large for this method here" : "its tolerance is too loose here",
    advice);
  diverged(what, at);
}

void HybridSimulator::settle()
{
  for (int k = 0; k < settings_.max_instant_transitions; ++k) {
    const GuardSet guards = guard_set(state_);
    State x;
    x << state_.q, state_.v;
    const Eigen::VectorXd values = guard_values(guards, state_.contact, state_.t, x, result_);
    Eigen::Index due = 0;
    while (due < values.size() && !(values[due] > settings_.margin)) {
      ++due;
    }
    if (due == values.size()) {
      return;
    }
    transition(guards.guards[static_cast<std::size_t>(due)]);
  }
  std::string last;
  const std::size_t first = events_.size() > 6 ? events_.size() - 6 : 0;
  for (std::size_t i = first; i < events_.size(); ++i) {
    last += (i > first ? ", '" : "'") + events_[i].event + "'";
  }
  throw ChatteringError(
    "chattering: more than " + std::to_string(settings_.max_instant_transitions)
    + " transitions at one instant; last events [" + last + "]");
}

void HybridSimulator::transition(Guard guard)
{
  const double t = state_.t;
  if (!(std::abs(t - instant_time_) <= settings_.event_tolerance * 10.0)) {
    instant_time_ = t;
    instant_modes_ = {{state_.contact.mode, state_.contact.side}};
  }
  TransitionOutcome outcome = apply_transition(
    dynamics_, settings_.friction, settings_.constants, state_, guard, result_);
  if (outcome.end != RunEnd::kNone) {
    throw Ended{outcome.end, state_};
  }
  const HybridState & next = outcome.state;
  const std::pair<int, int> key{next.contact.mode, next.contact.side};
  if (instant_modes_.count(key) > 0) {  // a cycle of single switches: a consistent mode
    resolve(guard);
    return;
  }
  instant_modes_.insert(key);
  events_.push_back({t, state_.contact.mode, next.contact.mode, name_of(guard), name_of(guard),
                     std::move(outcome.impulse), next.step_index, next.contact.side});
  if (next.contact.side != state_.contact.side) {
    inputs_ = rerooted(inputs_);
  }
  state_ = next;
  result_ = evaluate(state_);
}

void HybridSimulator::resolve(Guard guard)
{
  const auto found =
    resolve_contact_mode(dynamics_, settings_.friction, settings_.constants, state_, inputs_);
  const auto same = [](const Contact & a, const Contact & b) {
    return a.mode == b.mode && a.side == b.side && a.pivot == b.pivot
           && a.heel_anchor_y == b.heel_anchor_y && a.support_slide_dir == b.support_slide_dir
           && a.heel_slide_dir == b.heel_slide_dir;
  };
  if (!found || same(found->first.contact, state_.contact)) {
    rest(guard);
    return;
  }
  const HybridState & next = found->first;
  stats_.resolved_cycles += 1;
  events_.push_back({state_.t, state_.contact.mode, next.contact.mode, "R", name_of(guard), {},
                     next.step_index, next.contact.side});
  instant_modes_.insert({next.contact.mode, next.contact.side});
  state_ = next;
  result_ = found->second;
}

void HybridSimulator::rest(Guard guard)
{
  suppressed_[guard] = state_.t + settings_.chatter_dwell;
  stats_.suppressed_cycles += 1;
}

bool HybridSimulator::project(Eigen::VectorXd & residual)
{
  const HybridState & s = state_;
  const ConstraintRows c = dynamics_.constraints(s.contact, s.q);
  const double worst = c.position.cwiseAbs().maxCoeff();
  stats_.max_constraint_drift = std::max(stats_.max_constraint_drift, worst);
  if (worst < 1e-12 && (c.rows * s.v).cwiseAbs().maxCoeff() < 1e-12) {
    residual = c.position;  // nothing to correct
    return true;
  }
  const Vector18 q = project_positions(dynamics_, s.contact, s.q).first;
  const auto & act = dynamics_.mode(s.contact.mode).active;
  const auto n = static_cast<Eigen::Index>(act.size());
  const Eigen::MatrixXd rows = dynamics_.constraints(s.contact, q).rows;
  Eigen::MatrixXd jacobian(rows.rows(), n);
  Eigen::VectorXd v(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    jacobian.col(i) = rows.col(act[static_cast<std::size_t>(i)]);
    v[i] = s.v[act[static_cast<std::size_t>(i)]];
  }
  const Eigen::MatrixXd minv_jt = dynamics_.mass_matrix(s.contact, q).partialPivLu().solve(
    jacobian.transpose());
  v -= minv_jt * (jacobian * minv_jt).partialPivLu().solve(jacobian * v);
  state_.q = q;
  for (Eigen::Index i = 0; i < n; ++i) {
    state_.v[act[static_cast<std::size_t>(i)]] = v[i];
  }
  result_ = evaluate(state_);
  return false;
}

void HybridSimulator::check_speed(const HybridState & s)
{
  const double speed = s.v.cwiseAbs().maxCoeff();
  if (!(speed <= settings_.max_speed)) {
    diverged(format("speed %.3g beyond %g rad/s or m/s", speed, settings_.max_speed), s);
  }
}

void HybridSimulator::check_health(const Eigen::VectorXd * residual)
{
  const HybridState & s = state_;
  if (!s.q.allFinite() || !s.v.allFinite()) {
    diverged("non-finite state", s);
  }
  check_speed(s);
  if (!dynamics_.mode(s.contact.mode).constraints.empty()) {
    const double worst = residual != nullptr
                           ? residual->cwiseAbs().maxCoeff()
                           : dynamics_.constraints(s.contact, s.q).position.cwiseAbs().maxCoeff();
    stats_.max_constraint_residual = std::max(stats_.max_constraint_residual, worst);
    stats_.max_constraint_drift = std::max(stats_.max_constraint_drift, worst);
    if (worst > settings_.residual_bound) {
      diverged(format("constraint residual %.3g beyond %g", worst, settings_.residual_bound), s);
    }
  }
  if (dynamics_.frame_position(s.contact, s.q, "head_top")[2] < settings_.fall_height) {
    throw Ended{RunEnd::kFall, s};
  }
}

void HybridSimulator::diverged(const std::string & what, HybridState s)
{
  state_ = std::move(s);
  throw DivergenceError(what);
}

}  // namespace iceskate_native
