// One control period of the hybrid simulation in C++ (docs/model.md §6-§8): the input is held
// (zero-order hold), the mode's dynamics are integrated with a fixed-step method up to the next
// located event, its transition applied (a cascade of due transitions settled at once, a cycle
// of single switches replaced by the contact-consistent mode, a Zeno burst rested), and at the
// end the state is projected onto the active constraints and its health checked.
// iceskate_sim.physics.simulation.Simulator is its Python facade; tested against the period
// loop of the test oracle (tests/oracle/simulator.py, ReferenceSimulator.advance).
#pragma once

#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "iceskate_native/dynamics.hpp"
#include "iceskate_native/errors.hpp"
#include "iceskate_native/guards.hpp"
#include "iceskate_native/integrators.hpp"
#include "iceskate_native/transitions.hpp"

namespace iceskate_native
{

/// The state left the physical range (non-finite, too fast, constraints broken): the message
/// says what; HybridSimulator::state() is where.
class DivergenceError : public NativeError
{
public:
  using NativeError::NativeError;
};

/// More transitions at one instant than allowed (the message lists the last events).
class ChatteringError : public NativeError
{
public:
  using NativeError::NativeError;
};

/// Settings of a run: iceskate_sim.physics.simulation.SimulatorConfig's, the one place they are
/// declared with their defaults (the binding reads them by name).
struct SimulatorSettings
{
  double control_period{};  ///< [s], an integer multiple of step
  Method method{};
  double step{};             ///< [s]; the largest step of the adaptive method
  double rtol{};             ///< relative tolerance of the adaptive method
  double atol{};             ///< absolute tolerance of the adaptive method
  double event_tolerance{};  ///< [s]
  Friction friction;
  GuardConstants constants{};
  double margin{};           ///< a guard at most this positive is not due
  GuardTable guards;         ///< the guards of every mode, in the event log's order
  bool projection{};         ///< project onto the swing constraints after every period
  double residual_bound{};   ///< [m, rad] beyond which the run has diverged
  double fall_height{};      ///< [m] head-top height below which the robot has fallen
  double max_speed{};        ///< [m/s, rad/s] beyond which the run has diverged
  int max_instant_transitions{};
  double zeno_window{};      ///< [s] transitions this close count as one burst
  double chatter_dwell{};    ///< [s] a rested guard stays off this long
};

/// One entry of the event log: a guard's transition, or "R" (the contact-consistent mode
/// after a cycle of single switches of guard `guard`).
struct TransitionRecord
{
  double t = 0.0;
  int from_mode = 0;
  int to_mode = 0;
  std::string event;
  std::string guard;
  std::vector<double> impulse;  ///< [N s, N m s]
  int step_index = 0;
  int side = 0;
};

/// Counters of a run.
struct RunStatistics
{
  long steps = 0;
  long evaluations = 0;
  long control_periods = 0;
  double max_constraint_residual = 0.0;  ///< of the states a period ends in [m, rad]
  double max_constraint_drift = 0.0;     ///< a period leaves before its projection [m, rad]
  long suppressed_cycles = 0;
  long resolved_cycles = 0;
};

class HybridSimulator
{
public:
  /// How long the check of a physical end may take to reach one [s] (an end near a period's
  /// end may come a little later in the check's more accurate trajectory).
  static constexpr double kEndCheckTime = 0.02;

  /// A simulation from `initial` on `dynamics` (kept by reference: it must outlive this).
  HybridSimulator(Dynamics & dynamics, SimulatorSettings settings, HybridState initial);

  /// Back to the initial state; clears the log and the statistics. A state that ends the run
  /// at once sets ended().
  void reset();

  /// Continue from `s` (the event log, counters and rested guards kept; an ended run goes on).
  void set_state(const HybridState & s);

  /// Integrate one control period holding `inputs`. Throws DivergenceError, ChatteringError or
  /// NativeError; a physical end (fall, flight, toe-first touchdown) sets ended() instead, once
  /// rk45 at rtol 1e-8 (or the run's, if tighter) from the period's start under the same
  /// inputs reaches an end too within kEndCheckTime (whole periods, at least one): an end it
  /// does not reach is the method's (e.g. rk4 with too large a step), a DivergenceError with
  /// advice. An end the check cannot reach for an error of its own stands.
  void advance(const Inputs & inputs);

  const HybridState & state() const noexcept { return state_; }
  /// The state at the start of the last period after the transitions due then, and its
  /// dynamics under the period's inputs.
  const HybridState & start_state() const noexcept { return start_state_; }
  const DynamicsResult & start_result() const noexcept { return start_result_; }
  /// The dynamics at the current state under the last inputs.
  const DynamicsResult & result() const noexcept { return result_; }
  /// The inputs held over the last period (zero before the first).
  const Inputs & inputs() const noexcept { return inputs_; }
  const std::vector<TransitionRecord> & events() const noexcept { return events_; }
  const RunStatistics & statistics() const noexcept { return stats_; }
  RunEnd ended() const noexcept { return ended_; }
  const SimulatorSettings & settings() const noexcept { return settings_; }
  /// The dynamics it integrates.
  Dynamics & dynamics() noexcept { return dynamics_; }

private:
  struct Ended;  // a physical end of the run, thrown inside a period

  DynamicsResult evaluate(const HybridState & s);
  GuardSet guard_set(const HybridState & s) const;
  void settle();
  void transition(Guard guard);
  void resolve(Guard guard);
  void rest(Guard guard);
  bool project(Eigen::VectorXd & residual);
  void check_speed(const HybridState & s);
  void confirm_end(const HybridState & start, const std::map<Guard, double> & rested,
                   const Inputs & inputs, RunEnd end, const HybridState & at);
  void check_health(const Eigen::VectorXd * residual);
  [[noreturn]] void diverged(const std::string & what, HybridState s);

  Dynamics & dynamics_;
  SimulatorSettings settings_;
  HybridState initial_;
  HybridState state_;
  HybridState start_state_;
  DynamicsResult start_result_;
  DynamicsResult result_;
  Inputs inputs_;
  std::vector<TransitionRecord> events_;
  RunStatistics stats_;
  RunEnd ended_ = RunEnd::kNone;
  std::map<Guard, double> suppressed_;  // guard -> rested until [s]
  double instant_time_ = 0.0;           // the instant of the current transition cascade
  double adaptive_step_ = 0.0;          // the adaptive method's next step size [s] (0: none)
  std::set<std::pair<int, int>> instant_modes_;  // (mode, side) visited at that instant
};

}  // namespace iceskate_native
