#include "iceskate_native/transitions.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <tuple>

#include <Eigen/LU>

#include "iceskate_native/errors.hpp"

namespace iceskate_native
{

namespace
{

constexpr double kAtRest = 1.0e-7;         // m/s, rad/s: slow enough to switch without impulse
constexpr double kAccelTolerance = 1.0e-6;  // m/s^2, rad/s^2
constexpr double kProjected = 1.0e-14;     // residual [m, rad] at which projection stops
constexpr int kToe = 0;
constexpr int kHeel = 1;

bool on_edge(Support s) { return s == Support::kEdgeStuck || s == Support::kEdgeGliding; }
bool gliding(Support s) { return s == Support::kFlatGliding || s == Support::kEdgeGliding; }
bool pinned(Swing s) { return s == Swing::kHeelPinned || s == Swing::kFlatPinned; }
bool sliding(Swing s) { return s == Swing::kHeelSliding || s == Swing::kFlatSliding; }
bool sole_flat(Swing s) { return s == Swing::kFlatSliding || s == Swing::kFlatPinned; }
bool heel_only(Swing s) { return s == Swing::kHeelSliding || s == Swing::kHeelPinned; }

// A support foot: on an edge or flat, gliding or stuck.
Support support_with(bool edge, bool glide)
{
  return glide ? (edge ? Support::kEdgeGliding : Support::kFlatGliding)
               : (edge ? Support::kEdgeStuck : Support::kFlatStuck);
}

// A swing foot on the floor: flat or on its heel, pinned or sliding.
Swing swing_with(bool flat, bool pin)
{
  return flat ? (pin ? Swing::kFlatPinned : Swing::kFlatSliding)
              : (pin ? Swing::kHeelPinned : Swing::kHeelSliding);
}

// sign(x), with 0 counted as +1 (a direction, never zero)
double direction_of(double x) { return x < 0.0 ? -1.0 : 1.0; }

double leg_chain_sum(const Vector18 & x) { return x.segment<7>(1).sum(); }

// Impact of `state` onto the constraints of `contact` plus `extra` rows (first), positions first
// projected onto the new constraints (they hold only to the event tolerance at the instant).
struct Impact
{
  Vector18 q;
  Vector18 v;
  Eigen::VectorXd impulse;
};

Impact impact_into(
  Dynamics & dynamics, const HybridState & state, const Contact & contact,
  const Eigen::MatrixXd & extra = Eigen::MatrixXd(0, kCoordinates))
{
  Impact out;
  out.q = project_positions(dynamics, contact, state.q).first;
  const Eigen::MatrixXd constraint_rows = dynamics.constraints(contact, out.q).rows;
  Eigen::MatrixXd rows(extra.rows() + constraint_rows.rows(), kCoordinates);
  rows.topRows(extra.rows()) = extra;
  rows.bottomRows(constraint_rows.rows()) = constraint_rows;
  std::tie(out.v, out.impulse) = impact(dynamics, contact, out.q, state.v, rows);
  return out;
}

Contact with_mode(Contact c, const ModeTable & modes, Support support, Swing swing)
{
  c.mode = mode_for(modes, support, swing);
  return c;
}

HybridState reroot(Dynamics & dynamics, const GuardConstants & constants, const HybridState & s)
{
  const Contact & old = s.contact;
  const ModeTable & modes = dynamics.modes();
  const Swing swing = swing_of(dynamics.mode(old.mode));
  const Support support = support_with(!sole_flat(swing), !pinned(swing));
  const int number = mode_for(modes, support, Swing::kAir);
  const Mode & mode = dynamics.mode(number);
  HybridState out = s;
  out.q[kQ1] = mode.q1_active ? leg_chain_sum(s.q) : 0.0;
  out.v[kQ1] = mode.q1_active ? leg_chain_sum(s.v) : 0.0;
  for (int i = 0; i < 6; ++i) {  // q2'..q7' = -q7..-q2
    out.q[2 + i] = -s.q[7 - i];
    out.v[2 + i] = -s.v[7 - i];
  }
  const Eigen::Vector3d heel = dynamics.frame_position(old, s.q, "swing_heel");
  const Eigen::Vector3d heel_velocity = dynamics.frame_velocity(old, s.q, s.v, "swing_heel");
  out.q[kY0] = heel[1] - constants.sole_heel_y;
  out.v[kY0] = mode.y0_active ? heel_velocity[1] : 0.0;
  out.contact = Contact{};
  out.contact.mode = number;
  out.contact.side = 1 - old.side;
  out.contact.pivot = mode.q1_active ? kHeel : kToe;
  out.contact.heel_anchor_y = 0.0;
  out.contact.support_slide_dir = old.heel_slide_dir;
  out.step_index = s.step_index + 1;
  out.t_exchange = s.t;
  out.t_touchdown = std::numeric_limits<double>::quiet_NaN();
  return out;
}

// S1: inelastic impact onto C_hz; the heel then slides (Hs) or is pinned (Hp).
TransitionOutcome heel_strike(
  Dynamics & dynamics, const Friction & friction, const HybridState & state)
{
  const ModeTable & modes = dynamics.modes();
  const Support support = support_of(dynamics.mode(state.contact.mode));
  Contact slide = with_mode(state.contact, modes, support, Swing::kHeelSliding);
  slide.heel_slide_dir = 1.0;
  const Impact slid = impact_into(dynamics, state, slide);
  const double heel_vy = dynamics.frame_velocity(slide, slid.q, slid.v, "swing_heel")[1];
  Contact pin = with_mode(state.contact, modes, support, Swing::kHeelPinned);
  pin.heel_anchor_y = dynamics.frame_position(state.contact, slid.q, "swing_heel")[1];
  HybridState at = state;
  at.q = slid.q;
  const Impact held = impact_into(dynamics, at, pin);
  bool use_pin;
  if (friction.ice) {
    use_pin = heel_vy <= kSlideDeadBand;  // forward: slides; backward: the toe pick holds it
  } else {
    use_pin = std::abs(held.impulse[1]) <= friction.mu * held.impulse[0];
    if (!use_pin) {
      slide.heel_slide_dir = direction_of(heel_vy);
    }
  }
  const Impact & chosen = use_pin ? held : slid;
  TransitionOutcome out{state, {}, RunEnd::kNone};
  if (chosen.impulse[0] < 0.0) {  // the floor would have to pull: no contact is made
    return out;
  }
  out.state.q = held.q;
  out.state.v = chosen.v;
  out.state.contact = use_pin ? pin : slide;
  out.state.t_touchdown = state.t;
  out.impulse.assign(chosen.impulse.data(), chosen.impulse.data() + chosen.impulse.size());
  return out;
}

// Contact states reachable from `state` without an impact, most constrained first.
std::vector<Contact> candidates(const Dynamics & dynamics, const HybridState & state)
{
  const Contact & c = state.contact;
  const Mode & mode = dynamics.mode(c.mode);
  const Swing swing = swing_of(mode);
  const bool flat_ok = std::abs(state.q[kQ1]) < 1e-12 && std::abs(state.v[kQ1]) < kAtRest;
  const std::vector<int> pivots =
    mode.q1_active ? std::vector<int>{c.pivot} : std::vector<int>{kToe, kHeel};
  const bool stuck_ok = std::abs(state.v[kY0]) < kAtRest;
  const std::vector<double> glide_dirs = mode.y0_active && !stuck_ok
                                           ? std::vector<double>{c.support_slide_dir}
                                           : std::vector<double>{1.0, -1.0};
  std::vector<Swing> swings{Swing::kAir};
  if (swing != Swing::kAir) {
    swings = {Swing::kAir, Swing::kHeelSliding, Swing::kHeelPinned};
    if (sole_flat(swing)) {
      swings.push_back(Swing::kFlatSliding);
      swings.push_back(Swing::kFlatPinned);
    }
  }
  std::vector<Contact> out;
  for (Support support : {Support::kFlatStuck, Support::kEdgeStuck, Support::kFlatGliding,
                          Support::kEdgeGliding}) {
    const bool edge = on_edge(support);
    const bool glide = gliding(support);
    if ((!edge && !flat_ok) || (!glide && mode.y0_active && !stuck_ok)) {
      continue;
    }
    for (Swing s : {Swing::kFlatPinned, Swing::kFlatSliding, Swing::kHeelPinned,
                    Swing::kHeelSliding, Swing::kAir}) {
      if (std::find(swings.begin(), swings.end(), s) == swings.end()) {
        continue;
      }
      for (int pivot : edge ? pivots : std::vector<int>{c.pivot}) {
        for (double direction : glide ? glide_dirs : std::vector<double>{c.support_slide_dir}) {
          Contact candidate = with_mode(c, dynamics.modes(), support, s);
          candidate.pivot = pivot;
          candidate.support_slide_dir = direction;
          out.push_back(candidate);
        }
      }
    }
  }
  return out;
}

// All unilateral, friction and direction conditions of the candidate hold.
bool consistent(
  const Dynamics & dynamics, const HybridState & s, const DynamicsResult & r,
  const Friction & friction, const GuardConstants & k, const Mode & old)
{
  const Contact & c = s.contact;
  const Mode & mode = dynamics.mode(c.mode);
  if (r.support_normal < -k.force_band) {
    return false;
  }
  if (!mode.y0_active) {  // stuck support: the needed reaction inside the friction cone
    if (guard_value(Guard::kE4, c, s.q, s.v, r, friction, k) > 0.0) {
      return false;
    }
  } else if (std::abs(s.v[kY0]) < kAtRest && c.support_slide_dir * r.qdd[kY0] < -kAccelTolerance) {
    return false;
  }
  if (friction.ice && mode.y0_active && c.support_slide_dir < 0.0) {
    return false;
  }
  if (!mode.q1_active) {
    const double moment = r.support_wrench[3];
    if (moment - (k.sole_toe_y + k.cop_band) * r.support_normal > 0.0
        || (k.sole_heel_y - k.cop_band) * r.support_normal - moment > 0.0) {
      return false;
    }
  } else if (!old.q1_active) {  // a new edge: the sole must start to turn off the floor
    const double sign = c.pivot == kToe ? -1.0 : 1.0;
    if (sign * r.qdd[kQ1] < -kAccelTolerance) {
      return false;
    }
  }
  const Swing swing = swing_of(mode);
  if (swing == Swing::kAir) {
    return true;
  }
  if (r.multipliers[0] < -k.force_band) {
    return false;
  }
  if (pinned(swing) && guard_value(Guard::kS3, c, s.q, s.v, r, friction, k) > 0.0) {
    return false;
  }
  if (sole_flat(swing) && r.multipliers[2] < -k.moment_band) {
    return false;
  }
  if (heel_only(swing) && sole_flat(swing_of(old)) && leg_chain_sum(r.qdd) < -kAccelTolerance) {
    return false;  // the toe must lift
  }
  if (sliding(swing)) {
    const double heel_vy = r.swing_heel_velocity[1];
    if (friction.ice && c.heel_slide_dir < 0.0) {
      return false;
    }
    if (std::abs(heel_vy) > kAtRest && direction_of(heel_vy) != c.heel_slide_dir) {
      return false;
    }
  }
  return true;
}

}  // namespace

Support support_of(const Mode & mode)
{
  return support_with(mode.q1_active, mode.y0_active);
}

Swing swing_of(const Mode & mode)
{
  const bool heel_y = mode.multiplier_index(Constraint::kHeelY) >= 0;
  const bool flat = mode.multiplier_index(Constraint::kSoleFlat) >= 0;
  if (mode.constraints.empty()) {
    return Swing::kAir;
  }
  return swing_with(flat, heel_y);
}

int mode_for(const ModeTable & modes, Support support, Swing swing)
{
  for (const Mode & mode : modes) {
    if (support_of(mode) == support && swing_of(mode) == swing) {
      return mode.number;
    }
  }
  throw std::invalid_argument("the mode table has no mode for this support and swing state");
}

std::pair<Vector18, Eigen::VectorXd> impact(
  Dynamics & dynamics, const Contact & contact, const Vector18 & q, const Vector18 & v,
  const Eigen::MatrixXd & rows)
{
  const auto & act = dynamics.mode(contact.mode).active;
  const Eigen::MatrixXd mass = dynamics.mass_matrix(contact, q);
  const auto n = static_cast<Eigen::Index>(act.size());
  const Eigen::Index k = rows.rows();
  Eigen::MatrixXd system = Eigen::MatrixXd::Zero(n + k, n + k);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n + k);
  const Eigen::VectorXd v_active = v(act);
  system.topLeftCorner(n, n) = mass;
  system.bottomLeftCorner(k, n) = rows(Eigen::all, act);
  system.topRightCorner(n, k) = -rows(Eigen::all, act).transpose();
  rhs.head(n) = mass * v_active;
  const Eigen::PartialPivLU<Eigen::MatrixXd> lu(system);
  const Eigen::VectorXd x = lu.solve(rhs);
  if (!x.allFinite() || (lu.matrixLU().diagonal().array() == 0.0).any()) {
    throw NativeError("impact in mode " + std::to_string(contact.mode) + ": singular system");
  }
  Vector18 v_plus = Vector18::Zero();
  v_plus(act) = x.head(n);
  return {v_plus, x.tail(k)};
}

std::pair<Vector18, double> project_positions(
  Dynamics & dynamics, const Contact & contact, const Vector18 & q, int iterations)
{
  Vector18 out = q;
  double worst = 0.0;
  for (int iteration = 0; iteration < iterations; ++iteration) {
    const ConstraintRows c = dynamics.constraints(contact, out);
    if (c.position.size() == 0) {
      break;
    }
    const double largest = c.position.cwiseAbs().maxCoeff();
    if (iteration == 0) {
      worst = largest;
    }
    if (largest < kProjected) {
      break;
    }
    const Eigen::MatrixXd leg = c.rows.middleCols<6>(2);  // q2..q7 only
    out.segment<6>(2) -= leg.transpose() * (leg * leg.transpose()).partialPivLu().solve(c.position);
  }
  return {out, worst};
}

Inputs rerooted(const Inputs & inputs)
{
  Inputs out = inputs;
  for (const int i : {kY0, kQ1}) {  // between the floor and the old support foot: they end
    out.tau[i] = out.stiffness[i] = out.damping[i] = 0.0;
  }
  for (int i = 0; i < 6; ++i) {  // the sign of an effort follows its coordinate's; gains do not
    out.tau[2 + i] = -inputs.tau[7 - i];
    out.stiffness[2 + i] = inputs.stiffness[7 - i];
    out.damping[2 + i] = inputs.damping[7 - i];
  }
  return out;
}

TransitionOutcome apply_transition(
  Dynamics & dynamics, const Friction & friction, const GuardConstants & constants,
  const HybridState & state, Guard guard, const DynamicsResult & result)
{
  const ModeTable & modes = dynamics.modes();
  const Mode & mode = dynamics.mode(state.contact.mode);
  const Support support = support_of(mode);
  const Swing swing = swing_of(mode);
  TransitionOutcome out{state, {}, RunEnd::kNone};
  HybridState & s = out.state;
  Contact & c = s.contact;
  switch (guard) {
    case Guard::kE1:
    case Guard::kE2:
      c = with_mode(c, modes, support_with(true, gliding(support)), swing);
      c.pivot = guard == Guard::kE1 ? kToe : kHeel;
      s.q[kQ1] = 0.0;
      break;
    case Guard::kE3: {
      Eigen::MatrixXd pivot_row = Eigen::MatrixXd::Zero(1, kCoordinates);
      pivot_row(0, kQ1) = 1.0;
      HybridState flat = state;
      flat.q[kQ1] = 0.0;
      const Impact hit = impact_into(dynamics, flat, state.contact, pivot_row);
      out.impulse.assign(hit.impulse.data(), hit.impulse.data() + hit.impulse.size());
      s.q = hit.q;
      s.v = hit.v;
      s.v[kQ1] = 0.0;
      c = with_mode(c, modes, support_with(false, gliding(support)), swing);
      break;
    }
    case Guard::kE4:
      c = with_mode(c, modes, support_with(on_edge(support), true), swing);
      c.support_slide_dir = friction.ice ? 1.0 : direction_of(-result.support_friction);
      break;
    case Guard::kE5:
      s.v[kY0] = 0.0;
      c = with_mode(c, modes, support_with(on_edge(support), false), swing);
      break;
    case Guard::kE6:
      if (swing == Swing::kAir) {
        out.end = RunEnd::kFlight;
      } else {
        s = reroot(dynamics, constants, state);
      }
      break;
    case Guard::kS7:
      out.end = RunEnd::kToeFirst;
      break;
    case Guard::kS1:
      out = heel_strike(dynamics, friction, state);
      break;
    case Guard::kS2: {
      c = with_mode(c, modes, support, swing_with(sole_flat(swing), true));
      c.heel_anchor_y = result.swing_heel[1];
      const Impact hit = impact_into(dynamics, state, c);
      out.impulse.assign(hit.impulse.data(), hit.impulse.data() + hit.impulse.size());
      s.q = hit.q;
      s.v = hit.v;
      break;
    }
    case Guard::kS3:
      c = with_mode(c, modes, support, swing_with(sole_flat(swing), false));
      c.heel_slide_dir = friction.ice ? 1.0 : direction_of(-result.multipliers[1]);
      break;
    case Guard::kS4: {
      c = with_mode(c, modes, support, swing_with(true, pinned(swing)));
      const Impact hit = impact_into(dynamics, state, c);
      out.impulse.assign(hit.impulse.data(), hit.impulse.data() + hit.impulse.size());
      s.q = hit.q;
      s.v = hit.v;
      break;
    }
    case Guard::kS5:
      c = with_mode(c, modes, support, swing_with(false, pinned(swing)));
      break;
    case Guard::kS6:
      c = with_mode(c, modes, support, Swing::kAir);
      s.t_touchdown = std::numeric_limits<double>::quiet_NaN();
      // the end of the starting double support is the first swing's t_e: the paper's t_e is
      // when a foot becomes the swing foot, and the first one does so here
      if (state.step_index == 0 && state.t_touchdown <= state.t_exchange) {
        s.t_exchange = state.t;
      }
      break;
  }
  return out;
}

std::optional<std::pair<HybridState, DynamicsResult>> resolve_contact_mode(
  Dynamics & dynamics, const Friction & friction, const GuardConstants & constants,
  const HybridState & state, const Inputs & inputs)
{
  const Mode & old = dynamics.mode(state.contact.mode);
  for (Contact contact : candidates(dynamics, state)) {
    const Mode & mode = dynamics.mode(contact.mode);
    if (pinned(swing_of(mode)) && !pinned(swing_of(old))) {
      contact.heel_anchor_y = dynamics.frame_position(contact, state.q, "swing_heel")[1];
    }
    HybridState candidate = state;
    candidate.contact = contact;
    if (!mode.y0_active) {
      candidate.v[kY0] = 0.0;
    }
    if (!mode.q1_active) {
      candidate.v[kQ1] = 0.0;
    }
    const Eigen::MatrixXd rows = dynamics.constraints(contact, candidate.q).rows;
    if (rows.size() > 0 && (rows * candidate.v).cwiseAbs().maxCoeff() > 1e-6) {
      continue;
    }
    DynamicsResult result;
    try {
      result = dynamics.evaluate(contact, candidate.q, candidate.v, inputs);
    } catch (const NativeError &) {
      continue;
    } catch (const std::invalid_argument &) {
      continue;
    }
    if (consistent(dynamics, candidate, result, friction, constants, old)) {
      return std::make_pair(candidate, result);
    }
  }
  return std::nullopt;
}

}  // namespace iceskate_native
