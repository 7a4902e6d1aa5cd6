// The linearly implicit method of integrators.hpp: ROS34PW2 (Rang and Angermann, BIT 45, 2005),
// a four-stage Rosenbrock-W method of order 3 with an embedded method of order 2 and a dense
// output of order 3, L-stable and stiffly accurate (docs/model.md §8.1). Its matrix is
// I / (h gamma) - J with J the derivative of x' = (v, qdd) through the held stiffness K and
// damping D alone (the stiff part of eq. (7): joint damping, the commanded impedance, engaged soft
// stops), taken over eq. (7)'s system at the step's start (Dynamics::linearize):
//
//   J [dq; dv] = [dv; ddq],   [[M + e0 a^T, C], [G, 0]] [ddq; dlambda] = [-K dq - D dv; 0].
//
// A W-method keeps its order for any such approximation of the Jacobian; each of the stages
// evaluates eq. (7) once and solves with the step's factored matrix
// W = [[M + e0 a^T + c D + c^2 K, C], [G, 0]], c = h gamma.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

#include "iceskate_native/errors.hpp"
#include "iceskate_native/integrators.hpp"

namespace iceskate_native
{

namespace
{

constexpr int kStages = 4;
constexpr int kDenseDegree = 3;
constexpr int kEmbeddedOrder = 2;

/// ROS34PW2 in the variables u = Gamma k of Hairer and Wanner (Solving ODEs II, IV.7):
/// (I / (h gamma) - J) u_i = f(y + sum_j a_ij u_j) + sum_j c_ij / h u_j, y1 = y + sum_i m_i u_i,
/// the error e_i, the dense output y(theta) = y + sum_i sum_p d_ip theta^(p+1) u_i.
struct Scheme
{
  double gamma = 0.0;
  double a[kStages][kStages] = {};
  double c[kStages][kStages] = {};
  double m[kStages] = {};
  double e[kStages] = {};
  double d[kStages][kDenseDegree] = {};
};

/// The scheme from its published coefficients (alpha, Gamma with gamma on its diagonal, b, the
/// embedded b^, the dense output's b_i(theta) = sum_p bi_ip theta^(p+1)).
Scheme ros34pw2()
{
  constexpr double g = 4.3586652150845900e-01;
  const double alpha[kStages][kStages] = {
    {0.0, 0.0, 0.0, 0.0},
    {8.7173304301691801e-01, 0.0, 0.0, 0.0},
    {8.4457060015369423e-01, -1.1299064236484185e-01, 0.0, 0.0},
    {0.0, 0.0, 1.0, 0.0}};
  const double Gamma[kStages][kStages] = {
    {g, 0.0, 0.0, 0.0},
    {-8.7173304301691801e-01, g, 0.0, 0.0},
    {-9.0338057013044082e-01, 5.4180672388095326e-02, g, 0.0},
    {2.4212380706095346e-01, -1.2232505839045147e+00, 5.4526025533510214e-01, g}};
  const double b[kStages] = {2.4212380706095346e-01, -1.2232505839045147e+00,
                             1.5452602553351020e+00, 4.3586652150845900e-01};
  const double b_hat[kStages] = {3.7810903145819369e-01, -9.6042292212423178e-02,
                                 5.0000000000000000e-01, 2.1793326075422950e-01};
  const double bi[kStages][kDenseDegree] = {
    {1.0564298455794094, -1.3864882699759573, 0.5721822314575016},
    {2.296429974281067, -8.262611700275677, 4.742931142090097},
    {-1.307599564525376, 7.250979895056055, -4.398120075195578},
    {-1.045260255335102, 2.398120075195581, -0.9169932983520199}};
  double inverse[kStages][kStages] = {};  // Gamma^-1, lower triangular
  for (int i = 0; i < kStages; ++i) {
    inverse[i][i] = 1.0 / Gamma[i][i];
    for (int j = 0; j < i; ++j) {
      double sum = 0.0;
      for (int k = j; k < i; ++k) {
        sum += Gamma[i][k] * inverse[k][j];
      }
      inverse[i][j] = -sum / Gamma[i][i];
    }
  }
  Scheme s;
  s.gamma = g;
  for (int i = 0; i < kStages; ++i) {
    for (int j = 0; j < kStages; ++j) {
      for (int k = 0; k < kStages; ++k) {
        s.a[i][j] += alpha[i][k] * inverse[k][j];
      }
      s.c[i][j] = j < i ? -inverse[i][j] : 0.0;
    }
    for (int k = 0; k < kStages; ++k) {
      s.m[i] += b[k] * inverse[k][i];
      s.e[i] += (b[k] - b_hat[k]) * inverse[k][i];
      for (int p = 0; p < kDenseDegree; ++p) {
        s.d[i][p] += bi[k][p] * inverse[k][i];
      }
    }
  }
  return s;
}

const Scheme & scheme()
{
  static const Scheme ros = ros34pw2();
  return ros;
}

/// One stage's increment u of q and v.
struct Increment
{
  Vector18 q = Vector18::Zero();
  Vector18 v = Vector18::Zero();
};

/// The linear system of one step: W of the mode's n active coordinates and nc constraints,
/// factored, and what the stages' right-hand sides need of it.
class StepMatrix
{
public:
  StepMatrix(const Mode & mode, const LinearizedSystem & system, double c)
  : mode_(mode), stiffness_(system.stiffness), damping_(system.damping), c_(c),
    n_(system.n), nc_(system.nc)
  {
    SystemMatrix w = system.matrix;
    for (int k = 0; k < n_; ++k) {
      const int j = mode.active[static_cast<std::size_t>(k)];
      w(k, k) += c * system.damping[j] + c * c * system.stiffness[j];
    }
    structured_ = saddle_.factor(w, n_, nc_, system.row_change);
    if (!structured_) {  // e.g. a negative commanded damping: LU of the whole matrix
      lu_.compute(w);
      if ((lu_.matrixLU().diagonal().array() == 0.0).any()) {
        throw NativeError("ros34pw2: the step's matrix is singular in mode "
                          + std::to_string(mode.number));
      }
    }
  }

  /// The stage's increment u from r = (rq, rv) = f(x_i) + sum_j c_ij / h u_j:
  /// (I / c - J) u = r, i.e. uq = c (rq + uv) and uv = c rv + w with
  /// W [w; mu] = [-(c (c D + c^2 K) rv + c^2 K rq); 0] over the active coordinates.
  void solve(const Vector18 & rq, const Vector18 & rv, Increment & u)
  {
    const auto & act = mode_.active;
    rhs_.setZero(n_ + nc_);
    for (int k = 0; k < n_; ++k) {
      const int j = act[static_cast<std::size_t>(k)];
      const double added = c_ * damping_[j] + c_ * c_ * stiffness_[j];
      rhs_[k] = -(c_ * added * rv[j] + c_ * c_ * stiffness_[j] * rq[j]);
    }
    if (structured_) {
      saddle_.solve(rhs_, unknowns_);
    } else {
      unknowns_ = lu_.solve(rhs_);
    }
    u = Increment{};
    for (int k = 0; k < n_; ++k) {
      const int j = act[static_cast<std::size_t>(k)];
      u.v[j] = c_ * rv[j] + unknowns_[k];
      u.q[j] = c_ * (rq[j] + u.v[j]);
    }
  }

private:
  const Mode & mode_;
  Vector18 stiffness_;
  Vector18 damping_;
  double c_;
  int n_;
  int nc_;
  bool structured_ = false;
  SaddlePoint saddle_;
  Eigen::PartialPivLU<SystemMatrix> lu_;
  SystemVector rhs_;
  SystemVector unknowns_;
};

/// The step's state at theta in [0, 1] from its start x and increments (dense output).
State dense_state(const Scheme & s, const State & x, const std::array<Increment, kStages> & u,
                  double theta)
{
  State out = x;
  for (int i = 0; i < kStages; ++i) {
    double weight = 0.0;
    double power = theta;
    for (int p = 0; p < kDenseDegree; ++p) {
      weight += s.d[i][p] * power;
      power *= theta;
    }
    out.head<kCoordinates>() += weight * u[static_cast<std::size_t>(i)].q;
    out.tail<kCoordinates>() += weight * u[static_cast<std::size_t>(i)].v;
  }
  return out;
}

}  // namespace

Segment integrate_rosenbrock(
  Dynamics & dynamics, const Contact & contact, const Inputs & inputs,
  const Tolerances & tol, double event_tolerance, const GuardSet & guards, double t0,
  const State & x0, double t_end, const DynamicsResult & start, double & step)
{
  require_adaptive_settings(tol, event_tolerance, t0, t_end, "ros34pw2");
  const Scheme & s = scheme();
  const Mode & mode = dynamics.mode(contact.mode);
  Segment segment;
  double t = t0;
  State x = x0;
  DynamicsResult r0 = start;
  Eigen::VectorXd g0 = guard_values(guards, contact, t, x, r0);
  double h = std::min(step > 0.0 ? step : tol.max_step, tol.max_step);
  const double end_gap = 1e-12 * std::max(1.0, std::abs(t_end));
  std::array<Increment, kStages> u;
  while (t_end - t > end_gap) {
    const bool last_step = h >= t_end - t;
    const double h_try = last_step ? t_end - t : h;
    const Vector18 q0 = x.head<kCoordinates>();
    const Vector18 v0 = x.tail<kCoordinates>();
    const double gamma_h = h_try * s.gamma;
    StepMatrix matrix(mode, dynamics.linearize(contact, q0, v0, inputs, h_try), gamma_h);
    bool finite = true;
    for (int i = 0; i < kStages; ++i) {
      Vector18 q = q0;
      Vector18 v = v0;
      bool moved = false;
      for (int j = 0; j < i; ++j) {
        q += s.a[i][j] * u[static_cast<std::size_t>(j)].q;
        v += s.a[i][j] * u[static_cast<std::size_t>(j)].v;
        moved = moved || s.a[i][j] != 0.0;
      }
      if (!q.allFinite() || !v.allFinite()) {  // a step too large: rejected below
        finite = false;
        break;
      }
      Vector18 rq = v;
      Vector18 rv = moved ? dynamics.evaluate(contact, q, v, inputs).qdd : r0.qdd;
      segment.evaluations += moved ? 1 : 0;
      for (int j = 0; j < i; ++j) {
        rq += (s.c[i][j] / h_try) * u[static_cast<std::size_t>(j)].q;
        rv += (s.c[i][j] / h_try) * u[static_cast<std::size_t>(j)].v;
      }
      matrix.solve(rq, rv, u[static_cast<std::size_t>(i)]);
    }
    State x1 = x;
    State error = State::Zero();
    if (!finite) {
      x1.setConstant(std::numeric_limits<double>::quiet_NaN());
    }
    for (int i = 0; i < kStages; ++i) {
      const Increment & ui = u[static_cast<std::size_t>(i)];
      x1.head<kCoordinates>() += s.m[i] * ui.q;
      x1.tail<kCoordinates>() += s.m[i] * ui.v;
      error.head<kCoordinates>() += s.e[i] * ui.q;
      error.tail<kCoordinates>() += s.e[i] * ui.v;
    }
    double norm = 0.0;  // the error per entry over atol + rtol |x|, at its largest
    for (int i = 0; i < 2 * kCoordinates; ++i) {
      const double scale = tol.atol + tol.rtol * std::max(std::abs(x[i]), std::abs(x1[i]));
      norm = std::max(norm, std::abs(error[i]) / scale);
    }
    if (!x1.allFinite() || !error.allFinite()) {  // a step too large: rejected below
      norm = std::numeric_limits<double>::quiet_NaN();
    }
    const auto resized = [&](double factor) {
      return h_try * std::min(5.0, std::max(0.2, factor));
    };
    const double proposal =
      norm > 0.0 ? 0.9 * std::pow(norm, -1.0 / (kEmbeddedOrder + 1)) : 5.0;
    if (!(norm <= 1.0)) {  // rejected (a non-finite step too): a quarter or as the error says
      h = std::isfinite(norm) ? resized(proposal) : 0.25 * h_try;
      if (!(h > 1e-14 * std::max(1.0, std::abs(t)))) {
        throw NativeError("ros34pw2: the step size fell below 1e-14 s at t = " + std::to_string(t)
                          + " s (the error control cannot be met)");
      }
      continue;
    }
    segment.steps += 1;
    const double h_next = std::min(resized(proposal), tol.max_step);
    h = last_step ? std::max(h, h_next) : h_next;  // a step cut at t_end says little of the next
    step = h;
    const double t1 = last_step ? t_end : t + h_try;
    DynamicsResult r1 =
      dynamics.evaluate(contact, x1.head<kCoordinates>(), x1.tail<kCoordinates>(), inputs);
    ++segment.evaluations;
    const Eigen::VectorXd g1 = guard_values(guards, contact, t1, x1, r1);
    const double length = t1 - t;
    const State x_start = x;
    const auto at = [&](double offset, State & xs, DynamicsResult & rs) {
      xs = offset > 0.0 ? dense_state(s, x_start, u, offset / length) : x_start;
      rs = dynamics.evaluate(contact, xs.head<kCoordinates>(), xs.tail<kCoordinates>(), inputs);
      ++segment.evaluations;
    };
    if (first_crossing(guards, contact, event_tolerance, t, g0, g1, length, at, segment)) {
      return segment;
    }
    t = t1;
    x = x1;
    r0 = std::move(r1);
    g0 = g1;
  }
  return segment.reached(t_end, x, std::move(r0));
}

}  // namespace iceskate_native
