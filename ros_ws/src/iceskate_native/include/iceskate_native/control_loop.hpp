// Many control periods in one call (docs/architecture.md, "One run"): at every control instant
// t_k the controllers answer the observation of the current state (reading the robot through a
// Kinematics), the sum of their commands and the scene's push are held over [t_k, t_k+1]
// (zero-order hold) while HybridSimulator::advance integrates the period, and the sample of
// t_k goes into a SampleBlock (iceskate_sim.run.session.Session.run_periods). The same period
// runs under commands received from outside (hold(): the controller nodes of a ROS graph);
// both give the same samples bit for bit, whatever the block size.
#pragma once

#include <array>
#include <cstdint>
#include <exception>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "iceskate_native/cdr_rows.hpp"
#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"
#include "iceskate_native/sample_columns.hpp"
#include "iceskate_native/simulator.hpp"

namespace iceskate_native
{

class ModelKinematics;

/// An external force held over [start, start + duration) [s] at a frame's origin (a scene's
/// push): world force [N].
struct Push
{
  double start = 0.0;
  double duration = 0.0;
  std::string frame;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();

  bool active(double t) const { return start <= t && t < start + duration; }
};

/// A controller node's command for one control instant as the simulator receives it: the sum
/// of its sources (held over the period), each source's generalized force at the state it
/// answered (rows, in the order of `sources`; what is recorded) and its head target, if any.
struct ReceivedCommand
{
  JointCommand total;
  std::vector<std::string> sources;
  Eigen::Matrix<double, Eigen::Dynamic, kCoordinates, Eigen::RowMajor> efforts;
  bool has_head_target = false;
  Eigen::Vector3d head_target = Eigen::Vector3d::Zero();
};

/// The samples of consecutive control instants, column by column (row-major per sample): the
/// columns of ICESKATE_SAMPLE_COLUMNS (sample_columns.hpp), then each source's efforts. A
/// sample holds the state at t_k after the transitions due then, its dynamics under the
/// commands held over the period, each source's generalized force at the observed state, the
/// head-top placement observed at t_k, the /tf transforms of the URDF's links at the sample's
/// state and the head target steered to.
struct SampleBlock
{
  int count = 0;
#define ICESKATE_SAMPLE_FIELD(name, type, width, unit, saved, routes, meaning) \
  std::vector<type> name;
  ICESKATE_SAMPLE_COLUMNS(ICESKATE_SAMPLE_FIELD)
#undef ICESKATE_SAMPLE_FIELD
  std::size_t tf_pairs = 0;  ///< the /tf pairs of a sample
  /// The sources in the order they first answered; efforts[i]: 18 per sample, 0 where source i
  /// did not answer (present[k] bit i: it answered at sample k; "push" while a push acts).
  std::vector<std::string> sources;
  std::vector<std::vector<double>> efforts;

  /// Empty, the source list kept.
  void clear();
};

/// Call f(key, column, width) for every column of `block` (a SampleBlock, const or not) but
/// the efforts, in the order of ICESKATE_SAMPLE_COLUMNS: its name, its vector and its values
/// per sample (1: a 1-D array).
template <class Block, class F>
void for_each_column(Block & block, F && f)
{
#define ICESKATE_SAMPLE_VISIT(name, type, width, unit, saved, routes, meaning) \
  f(#name, block.name, sample_width(static_cast<std::size_t>(width), block.tf_pairs));
  ICESKATE_SAMPLE_COLUMNS(ICESKATE_SAMPLE_VISIT)
#undef ICESKATE_SAMPLE_VISIT
}

/// The column `name` of `block` (its key in take_block()'s dict; "efforts.<i>" for source i's
/// efforts), for CdrProgram::write.
/// \throws std::invalid_argument for a name that is no column.
Column column_of(const SampleBlock & block, const std::string & name);

/// The loop of control periods over a simulator, its controllers (in summing order) and the
/// scene's pushes. It holds references: the simulator, the kinematics and the controllers
/// must outlive it (the kinematics may be null for a loop without controllers, which only
/// holds received commands). Not thread-safe.
class ControlLoop
{
public:
  /// head_origin: the head target recorded while no controller steers one (psi at t = 0);
  /// tf_pairs: the (parent, child) link frames of /tf, parent "world" for the world frame
  /// (std::invalid_argument if a support model lacks a frame).
  ControlLoop(
    HybridSimulator & simulator, Kinematics * kinematics, std::vector<Controller *> controllers,
    std::vector<Push> pushes, const Eigen::Vector3d & head_origin,
    const std::vector<std::pair<std::string, std::string>> & tf_pairs);

  /// Up to `periods` control periods into `block` (cleared first); returns the samples taken.
  /// It stops after a period in which the run ended physically (HybridSimulator::ended), and
  /// before recording a period whose physics or controller threw: error() then holds that
  /// exception and the simulator is where it failed.
  int run(int periods, SampleBlock & block);

  /// One control period under `commands` (one per controller node, in summing order) instead
  /// of the loop's own controllers: the same sum, hold, push and sample as run(), the sample
  /// appended to `block` (not cleared). Returns false if the physics failed: error() then
  /// holds why, as after run().
  bool hold(const std::vector<ReceivedCommand> & commands, SampleBlock & block);

  /// The live view of the current state, what the simulator publishes at t_k before the
  /// commands of t_k exist: `block` (cleared) gets one sample of the current state, its
  /// dynamics under the inputs held over the last period, the held input's generalized force
  /// at the state as the one source "held" and the head target of that period (head_origin
  /// before the first).
  void live(SampleBlock & block);

  /// What stopped the last run() or hold() early (null: nothing).
  std::exception_ptr error() const noexcept { return error_; }
  /// Whether that came from the simulator's period (else from a controller or the sample).
  bool physics_failed() const noexcept { return physics_failed_; }

private:
  void step(SampleBlock & block);
  void period(const std::vector<ReceivedCommand> & commands, SampleBlock & block);
  std::size_t source_index(SampleBlock & block, const std::string & name);
  /// frame_ids_ of the support model of `contact`.
  const std::vector<int> & frame_ids(const Contact & contact) const;
  /// Append a sample but its efforts and `present` to `block`: the state `s`, its dynamics
  /// `r`, the head-top placement, the /tf transforms of the link placements (placements_ from
  /// 1 on) and the head target.
  void sample(
    SampleBlock & block, const HybridState & s, const DynamicsResult & r, const Placement & head,
    const Eigen::Vector3d & target) const;

  HybridSimulator & simulator_;
  Kinematics * kinematics_;
  ModelKinematics * model_kinematics_;  // kinematics_ if it can adopt the dynamics' passes
  std::vector<Controller *> controllers_;
  std::vector<Push> pushes_;
  Eigen::Vector3d head_origin_;
  Eigen::Vector3d held_target_;            // the head target of the last period
  std::vector<std::string> frames_;        // head_top, then the /tf links: a sample's placements
  std::array<std::vector<int>, 4> frame_ids_;  // their indices in support model side * 2 + pivot
  std::vector<Placement> placements_;      // theirs, reused
  std::vector<std::pair<int, int>> tf_;    // /tf pairs: indices in frames_ (parent 0: world)
  std::vector<ControllerOutput> outputs_;  // one per controller, reused
  std::vector<ReceivedCommand> commands_;  // their commands as a node would send them
  std::exception_ptr error_;
  bool physics_failed_ = false;
};

}  // namespace iceskate_native
