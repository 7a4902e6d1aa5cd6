// The resets of the hybrid automaton (docs/model.md §6-§7): perfectly inelastic impacts
// projected on the new constraint set, coordinate changes (add or drop q1 or y0), the support
// exchange that re-roots the tree, and the contact-consistent mode that replaces a cycle of
// single switches at one instant. Tested against the test oracle's automaton
// (tests/oracle/automaton.py: apply_transition, reroot, impact, project_positions,
// resolve_contact_mode).
#pragma once

#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "iceskate_native/dynamics.hpp"
#include "iceskate_native/guards.hpp"

namespace iceskate_native
{

/// Support-foot states of Table 2: flat or on an edge (q1), stuck or gliding (y0).
enum class Support
{
  kFlatStuck,    // F-S
  kEdgeStuck,    // R-S
  kFlatGliding,  // F-G
  kEdgeGliding   // R-G
};

/// Swing-foot states of Table 2: in the air, heel touching, sole flat; sliding or pinned.
enum class Swing
{
  kAir,          // A
  kHeelSliding,  // Hs
  kHeelPinned,   // Hp
  kFlatSliding,  // Fs
  kFlatPinned    // Fp
};

Support support_of(const Mode & mode);
Swing swing_of(const Mode & mode);

/// The number of the mode made of a support and a swing state.
int mode_for(const ModeTable & modes, Support support, Swing swing);

/// Continuous and discrete state (iceskate_sim.physics.hybrid.HybridState).
struct HybridState
{
  double t = 0.0;  ///< [s]
  Vector18 q = Vector18::Zero();
  Vector18 v = Vector18::Zero();
  Contact contact;
  int step_index = 0;       ///< support exchanges so far
  double t_exchange = 0.0;  ///< time of the last support exchange [s]
  double t_touchdown = std::numeric_limits<double>::quiet_NaN();  ///< swing heel strike [s]
};

/// Physical ends of a run the paper's model cannot represent (not errors).
enum class RunEnd
{
  kNone,
  kFlight,     // E6 with the swing foot in the air: both feet off the floor
  kToeFirst,   // S7: the swing toe touches down first
  kFall        // the head top fell below the fall height
};

/// The outcome of a reset: the new state, the impulses of its impact [N s, N m s] (none for a
/// change without impact), or the end of the run it means.
struct TransitionOutcome
{
  HybridState state;
  std::vector<double> impulse;
  RunEnd end = RunEnd::kNone;
};

/// Velocity dead band [m/s] of the heel strike: a heel moving backward slower than this is
/// pinned by the toe pick, not sliding (ice rule).
constexpr double kSlideDeadBand = 1.0e-4;

/// Perfectly inelastic impact onto `rows` (k x 18): solves [M -J^T; J 0] [v+; Pi] = [M v-; 0]
/// over the active coordinates of contact.mode; returns v+ (18) and the impulses Pi (k).
std::pair<Vector18, Eigen::VectorXd> impact(
  Dynamics & dynamics, const Contact & contact, const Vector18 & q, const Vector18 & v,
  const Eigen::MatrixXd & rows);

/// Gauss-Newton projection of q onto the active swing constraints moving q2..q7 only (the
/// support coordinates carry guards of their own); returns the projected q and the largest
/// residual before projecting [m, rad].
std::pair<Vector18, double> project_positions(
  Dynamics & dynamics, const Contact & contact, const Vector18 & q, int iterations = 4);

/// The same physical input in the coordinates of the other support foot (the support
/// exchange's map q2'..q7' = -q7..-q2 applied to the leg joints' inputs): a command held over a
/// control period keeps acting on the same motors when the tree re-roots inside the period;
/// its y0 and q1 entries act between the floor and the old support foot, which has left it, and
/// end.
Inputs rerooted(const Inputs & inputs);

/// The reset of `guard` at `state` (located on the guard's zero) with its dynamics `result`.
TransitionOutcome apply_transition(
  Dynamics & dynamics, const Friction & friction, const GuardConstants & constants,
  const HybridState & state, Guard guard, const DynamicsResult & result);

/// A contact-consistent mode at an instant where single switches cycle: the most constrained
/// mode reachable without an impact whose solution satisfies every unilateral, friction-cone,
/// CoP and direction condition, with its dynamics under `inputs`; none if there is none.
std::optional<std::pair<HybridState, DynamicsResult>> resolve_contact_mode(
  Dynamics & dynamics, const Friction & friction, const GuardConstants & constants,
  const HybridState & state, const Inputs & inputs);

}  // namespace iceskate_native
