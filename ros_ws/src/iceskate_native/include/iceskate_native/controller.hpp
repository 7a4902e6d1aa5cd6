// The controller interface of the native core: what a control law sees (Observation, the
// counterpart of iceskate_sim.model.observation.Observation), what it answers (ControllerOutput: one
// JointCommand per source, as iceskate_sim.model.command), and the abstract Controller the simulator
// calls once per control period with a Kinematics it owns. Eigen only: the controller packages
// (visual_lifting, gait_manager) implement Controller against these headers without Pinocchio.
// Units: SI (m, rad, s; N, N m; N m/rad, N m s/rad).
#pragma once

#include <algorithm>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "iceskate_native/coordinates.hpp"
#include "iceskate_native/kinematics.hpp"
#include "iceskate_native/modes.hpp"

namespace iceskate_native
{

/// The state a control law acts on, at a control instant.
struct Observation
{
  double t = 0.0;                 ///< simulation time [s]
  Vector18 q = Vector18::Zero();  ///< [y0, q1..q17] (m, rad); locked entries held
  Vector18 v = Vector18::Zero();  ///< velocities; locked entries 0
  int mode = 1;                   ///< Table 2 mode number (1-20)
  int side = 0;                   ///< support side: 0 right, 1 left (the paper's a)
  int pivot = 0;                  ///< support pivot edge: 0 toe, 1 heel
  int step_index = 0;             ///< support exchanges so far
  double t_exchange = 0.0;        ///< t_e, time of the last support exchange [s]
  double heel_anchor_y = 0.0;     ///< y_h* of a pinned swing heel [m]
  /// Time of the swing heel strike of the current step [s]; NaN while the swing foot has not
  /// touched down since the last exchange.
  double t_touchdown = std::numeric_limits<double>::quiet_NaN();

  SupportState support() const { return {mode, side, pivot}; }
};

/// Where the swing foot is, from a mode's swing constraints (Table 2's swing codes): in the air
/// (A), on its heel (Hs, Hp) or flat (Fs, Fp).
enum class SwingContact
{
  kAir,
  kHeel,
  kSole
};

inline SwingContact swing_contact(const Mode & mode)
{
  if (mode.constraints.empty()) {
    return SwingContact::kAir;
  }
  const auto & c = mode.constraints;
  return std::find(c.begin(), c.end(), Constraint::kSoleFlat) != c.end() ? SwingContact::kSole
                                                                          : SwingContact::kHeel;
}

/// effort + stiffness * (reference - q) - damping * v per coordinate; without an impedance the
/// effort alone (stiffness, damping and reference unused).
struct JointCommand
{
  Vector18 effort = Vector18::Zero();
  bool has_impedance = false;
  Vector18 stiffness = Vector18::Zero();  ///< >= 0
  Vector18 damping = Vector18::Zero();    ///< >= 0
  Vector18 reference = Vector18::Zero();

  /// The generalized force this command applies at (q, v) [N m, N].
  Vector18 torque(const Vector18 & q, const Vector18 & v) const
  {
    if (!has_impedance) {
      return effort;
    }
    return effort + stiffness.cwiseProduct(reference - q) - damping.cwiseProduct(v);
  }

  /// A plain torque, no impedance.
  void set_torque(const Vector18 & tau)
  {
    effort = tau;
    has_impedance = false;
  }
};

/// One source's command, by source name.
struct SourceCommand
{
  std::string source;
  JointCommand command;
};

/// What a controller answers at one instant: its sources' commands in its order, and the head
/// target psi_d = (y [m], z [m], pitch [rad]) it steers to, if it has one.
struct ControllerOutput
{
  std::vector<SourceCommand> sources;
  bool has_head_target = false;
  Eigen::Vector3d head_target = Eigen::Vector3d::Zero();

  /// Empty, keeping the storage (a caller reuses one output every period).
  void clear()
  {
    sources.clear();
    has_head_target = false;
  }

  /// A new source at the end (default command: zero torque, no impedance).
  JointCommand & add(const char * source)
  {
    sources.emplace_back();
    sources.back().source = source;
    return sources.back().command;
  }

  /// One command applying the sum of the sources' (iceskate_sim.model.command.JointCommand.total,
  /// operation for operation): efforts, stiffnesses and dampings add up in order; the reference
  /// is the stiffness-weighted mean (0 where no stiffness acts), or the reference of the one
  /// source with an impedance.
  JointCommand total() const
  {
    JointCommand sum;
    const JointCommand * only = nullptr;
    int impedances = 0;
    Vector18 pull = Vector18::Zero();
    for (const auto & [source, c] : sources) {
      sum.effort += c.effort;
      if (c.has_impedance) {
        only = &c;
        ++impedances;
        sum.stiffness += c.stiffness;
        sum.damping += c.damping;
        pull += c.stiffness.cwiseProduct(c.reference);
      }
    }
    if (impedances == 1) {
      sum.stiffness = only->stiffness;
      sum.damping = only->damping;
      sum.reference = only->reference;
    } else if (impedances > 1) {
      for (int i = 0; i < kCoordinates; ++i) {
        sum.reference[i] = sum.stiffness[i] > 0.0 ? pull[i] / sum.stiffness[i] : 0.0;
      }
    }
    sum.has_impedance = impedances > 0;
    return sum;
  }
};

/// A control law: compute() answers one observation, reading the robot model through
/// `kinematics` (owned by the caller, one per thread), and fills `out` (cleared first). A law
/// may keep state between calls (e.g. a pose latched at t = 0); it throws a std::runtime_error
/// subclass when its command is not finite.
class Controller
{
public:
  virtual ~Controller() = default;
  virtual void compute(
    const Observation & obs, Kinematics & kinematics, ControllerOutput & out) = 0;
};

}  // namespace iceskate_native
