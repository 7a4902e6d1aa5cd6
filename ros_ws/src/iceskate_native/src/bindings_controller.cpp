// Bindings of the controller interface (controller.hpp, kinematics.hpp) and ModelKinematics,
// part of iceskate_native._kernel: the base types Kinematics and Controller, which the
// controller packages' modules (visual_lifting._law, gait_manager._law) derive from and receive
// (nanobind shares registered types between modules built with the same nanobind), the
// Observation a law answers, and the queries of a Kinematics (tested against the Python model).
// Controller is subclassable in Python (its trampoline PythonController, python_controller.hpp):
// a controller written in Python runs inside the native ControlLoop.
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/map.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include "bindings.hpp"
#include "python_controller.hpp"
#include "iceskate_native/checks.hpp"
#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"
#include "iceskate_native/model.hpp"
#include "iceskate_native/model_kinematics.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace iceskate_native::bindings
{

namespace
{

Frame frame_named(const std::string & name)
{
  for (std::size_t k = 0; k < kFrameNames.size(); ++k) {
    if (name == kFrameNames[k]) {
      return static_cast<Frame>(k);
    }
  }
  throw std::invalid_argument("unknown frame '" + name + "' (head_top, swing_heel, support_toe, "
                              "support_heel or pelvis_centre)");
}

void construct_kinematics(
  ModelKinematics * self, const std::vector<RobotModel> & models,
  const std::vector<Frames> & frames, const std::vector<ModeRow> & modes, double total_mass)
{
  new (self) ModelKinematics(support_models(models, frames), mode_table(modes), total_mass);
}

void construct_observation(
  Observation * self, double t, const Vector & q, const Vector & v, std::int64_t mode,
  std::int64_t side, std::int64_t pivot, std::int64_t step_index, double t_exchange,
  double heel_anchor_y, double t_touchdown)
{
  if (!std::isfinite(t) || !std::isfinite(t_exchange) || !std::isfinite(heel_anchor_y)) {
    throw std::invalid_argument("the observation's t, t_exchange and heel_anchor_y must be "
                                "finite");
  }
  if (std::isinf(t_touchdown)) {
    throw std::invalid_argument("the observation's t_touchdown must be finite or NaN (none)");
  }
  if (mode < 1 || mode > std::numeric_limits<int>::max()) {  // the table's: Kinematics::mode
    throw std::invalid_argument("observation mode " + std::to_string(mode) + " is not a mode");
  }
  if (side < 0 || side > 1 || pivot < 0 || pivot > 1 || step_index < 0) {
    throw std::invalid_argument(
      "observation side and pivot must be 0 or 1, and step_index >= 0");
  }
  constexpr std::int64_t kMostSteps = std::numeric_limits<int>::max();
  if (step_index > kMostSteps) {  // a legal uint32 of a GaitState
    throw std::invalid_argument("observation step_index " + std::to_string(step_index)
                                + " is beyond the " + std::to_string(kMostSteps)
                                + " steps a run can take");
  }
  new (self) Observation{
    t, vector18(q, "q"), vector18(v, "v"), static_cast<int>(mode), static_cast<int>(side),
    static_cast<int>(pivot), static_cast<int>(step_index), t_exchange, heel_anchor_y,
    t_touchdown};
}

/// A controller's answer at obs as an EffortCommand carries it (see kCommandDoc).
std::tuple<Eigen::VectorXd, bool, bool, std::vector<std::string>> command_values(
  Controller & self, const Observation & obs, Kinematics & kinematics)
{
  ControllerOutput out;
  self.compute(obs, kinematics, out);
  const JointCommand total = out.total();
  const Eigen::Index impedance = total.has_impedance ? kCoordinates : 0;
  const Eigen::Index source_count = static_cast<Eigen::Index>(out.sources.size());
  Eigen::VectorXd values(
    kCoordinates + 3 * impedance + kCoordinates * source_count + (out.has_head_target ? 3 : 0));
  values << total.effort, total.stiffness.head(impedance), total.damping.head(impedance),
    total.reference.head(impedance), Eigen::VectorXd::Zero(kCoordinates * source_count),
    out.head_target.head(out.has_head_target ? 3 : 0);
  std::vector<std::string> names;
  Eigen::Index at = kCoordinates + 3 * impedance;
  for (const auto & [source, command] : out.sources) {
    values.segment<kCoordinates>(at) = command.torque(obs.q, obs.v);
    at += kCoordinates;
    names.push_back(source);
  }
  return {std::move(values), total.has_impedance, out.has_head_target, std::move(names)};
}

constexpr const char * kCommandDoc =
  "The answer at obs as an EffortCommand carries it (iceskate_sim.model.command.CommandValues), "
  "in one vector: the sum of the sources' commands (effort, then stiffness, damping and "
  "reference if it has an impedance), each source's generalized force at (q, v) (18 per "
  "source), the head target (y, z, pitch) if it steers one; then whether it has an "
  "impedance, whether it has a head target and the sources' names in order.";

SupportState support_state(int mode, int side, int pivot)
{
  if (side < 0 || side > 1 || pivot < 0 || pivot > 1) {
    throw std::invalid_argument("side and pivot must be 0 or 1");
  }
  return {mode, side, pivot};
}

}  // namespace

void bind_controller(nb::module_ & m)
{
  nb::class_<Kinematics>(
    m, "Kinematics",
    "The robot model as the control laws read it (abstract; ModelKinematics implements it). "
    "Joints are numbered by coordinate (0: y0, i: q_i); states by (mode, side 0 right / 1 "
    "left, pivot 0 toe / 1 heel).")
    .def_prop_ro("total_mass", &Kinematics::total_mass, "Total mass [kg].")
    .def(
      "head_pose",
      [](Kinematics & self, int mode, int side, int pivot, const Vector & q) {
        const auto pose = self.head_pose(support_state(mode, side, pivot), vector18(q, "q"));
        return std::make_tuple(Eigen::VectorXd(pose.psi), Eigen::MatrixXd(pose.jacobian));
      },
      "mode"_a, "side"_a, "pivot"_a, "q"_a,
      "(psi (3,), J_H (3, 18)): head-top (y [m], z [m], pitch [rad]) and d psi / d q.")
    .def(
      "gravity",
      [](Kinematics & self, int mode, int side, int pivot, const Vector & q) {
        return Eigen::VectorXd(self.gravity(support_state(mode, side, pivot), vector18(q, "q")));
      },
      "mode"_a, "side"_a, "pivot"_a, "q"_a, "g(q) (18,) [N m, N]; locked entries 0.")
    .def(
      "swing_heel_z_row",
      [](Kinematics & self, int mode, int side, int pivot, const Vector & q) {
        return Eigen::VectorXd(
          self.swing_heel_z_row(support_state(mode, side, pivot), vector18(q, "q")));
      },
      "mode"_a, "side"_a, "pivot"_a, "q"_a, "d z_heel / d q of the swing heel (18,).")
    .def(
      "centre_of_mass",
      [](Kinematics & self, int mode, int side, int pivot, const Vector & q, const Vector & v) {
        const auto com =
          self.centre_of_mass(support_state(mode, side, pivot), vector18(q, "q"),
                              vector18(v, "v"));
        return std::make_tuple(Eigen::VectorXd(com.position), Eigen::VectorXd(com.velocity),
                               Eigen::VectorXd(com.jacobian_y));
      },
      "mode"_a, "side"_a, "pivot"_a, "q"_a, "v"_a,
      "(position [m], velocity [m/s], d y_com / d q (18,)) of the centre of mass.")
    .def(
      "frame_position",
      [](Kinematics & self, int mode, int side, int pivot, const Vector & q,
         const std::string & frame) {
        return Eigen::VectorXd(self.frame_position(
          support_state(mode, side, pivot), vector18(q, "q"), frame_named(frame)));
      },
      "mode"_a, "side"_a, "pivot"_a, "q"_a, "frame"_a, "World position [m] of a frame.")
    .def(
      "joint_position",
      [](Kinematics & self, int mode, int side, int pivot, const Vector & q, int joint) {
        return Eigen::VectorXd(
          self.joint_position(support_state(mode, side, pivot), vector18(q, "q"), joint));
      },
      "mode"_a, "side"_a, "pivot"_a, "q"_a, "joint"_a, "World position [m] of a joint.")
    .def(
      "joint_velocity",
      [](Kinematics & self, int mode, int side, int pivot, const Vector & q, const Vector & v,
         int joint) {
        return Eigen::VectorXd(self.joint_velocity(
          support_state(mode, side, pivot), vector18(q, "q"), vector18(v, "v"), joint));
      },
      "mode"_a, "side"_a, "pivot"_a, "q"_a, "v"_a, "joint"_a,
      "World-aligned linear velocity [m/s] of a joint's origin.")
    .def(
      "joint_placement",
      [](const Kinematics & self, int side, int pivot, int joint) {
        return Eigen::VectorXd(self.joint_placement(side, pivot, joint));
      },
      "side"_a, "pivot"_a, "joint"_a, "A joint's placement in its parent joint [m].")
    .def(
      "frame_offset",
      [](const Kinematics & self, int side, int pivot, const std::string & frame) {
        return Eigen::VectorXd(self.frame_offset(side, pivot, frame_named(frame)));
      },
      "side"_a, "pivot"_a, "frame"_a, "A frame's position in its parent joint [m].")
    // the same queries at an observation's state (a Python controller's compute)
    .def(
      "head_pose",
      [](Kinematics & self, const Observation & obs) {
        const auto pose = self.head_pose(obs.support(), obs.q);
        return std::make_tuple(Eigen::VectorXd(pose.psi), Eigen::MatrixXd(pose.jacobian));
      },
      "obs"_a, "(psi (3,), J_H (3, 18)) at obs's state.")
    .def(
      "gravity",
      [](Kinematics & self, const Observation & obs) {
        return Eigen::VectorXd(self.gravity(obs.support(), obs.q));
      },
      "obs"_a, "g(q) (18,) [N m, N] at obs's state; locked entries 0.")
    .def(
      "swing_heel_z_row",
      [](Kinematics & self, const Observation & obs) {
        return Eigen::VectorXd(self.swing_heel_z_row(obs.support(), obs.q));
      },
      "obs"_a, "d z_heel / d q of the swing heel (18,) at obs's state.")
    .def(
      "centre_of_mass",
      [](Kinematics & self, const Observation & obs) {
        const auto com = self.centre_of_mass(obs.support(), obs.q, obs.v);
        return std::make_tuple(Eigen::VectorXd(com.position), Eigen::VectorXd(com.velocity),
                               Eigen::VectorXd(com.jacobian_y));
      },
      "obs"_a, "(position [m], velocity [m/s], d y_com / d q (18,)) at obs's state.")
    .def(
      "frame_position",
      [](Kinematics & self, const Observation & obs, const std::string & frame) {
        return Eigen::VectorXd(self.frame_position(obs.support(), obs.q, frame_named(frame)));
      },
      "obs"_a, "frame"_a, "World position [m] of a frame at obs's state.")
    .def(
      "joint_position",
      [](Kinematics & self, const Observation & obs, int joint) {
        return Eigen::VectorXd(self.joint_position(obs.support(), obs.q, joint));
      },
      "obs"_a, "joint"_a, "World position [m] of a joint at obs's state.")
    .def(
      "joint_velocity",
      [](Kinematics & self, const Observation & obs, int joint) {
        return Eigen::VectorXd(self.joint_velocity(obs.support(), obs.q, obs.v, joint));
      },
      "obs"_a, "joint"_a, "World-aligned linear velocity [m/s] of a joint's origin at obs.")
    .def(
      "active",
      [](const Kinematics & self, int mode) {
        const Mode & row = self.mode(mode);
        return Eigen::VectorXi(Eigen::Map<const Eigen::VectorXi>(
          row.active.data(), static_cast<Eigen::Index>(row.active.size())));
      },
      "mode"_a, "The coordinates active in Table 2's mode `mode` (increasing; 0: y0, i: q_i).");

  nb::class_<ModelKinematics, Kinematics>(
    m, "ModelKinematics",
    "Kinematics on Pinocchio over the four support models (index side * 2 + pivot, as "
    "Dynamics takes them), with its own workspaces: one instance per thread.")
    .def("__init__", &construct_kinematics, "models"_a, "frames"_a, "modes"_a, "total_mass"_a)
    .def("can_adopt_from", &ModelKinematics::can_adopt_from, "dynamics"_a,
         "Whether a ControlLoop over `dynamics` hands these kinematics the joint placements, "
         "Jacobians and velocities of its passes at each period's state: the same four support "
         "models, every joint revolute or prismatic.");

  nb::class_<Observation>(
    m, "Observation",
    "The state a control law answers (iceskate_sim.model.observation.Observation with side 0 right / "
    "1 left, pivot 0 toe / 1 heel; t_touchdown NaN: none). ValueError for a bad field.")
    .def(
      "__init__", &construct_observation, "t"_a, "q"_a, "v"_a, "mode"_a, "side"_a, "pivot"_a,
      "step_index"_a, "t_exchange"_a, "heel_anchor_y"_a, "t_touchdown"_a)
    .def_ro("t", &Observation::t)
    .def_prop_ro("q", [](const Observation & o) { return Eigen::VectorXd(o.q); })
    .def_prop_ro("v", [](const Observation & o) { return Eigen::VectorXd(o.v); })
    .def_ro("mode", &Observation::mode)
    .def_ro("side", &Observation::side)
    .def_ro("pivot", &Observation::pivot)
    .def_ro("step_index", &Observation::step_index)
    .def_ro("t_exchange", &Observation::t_exchange)
    .def_ro("heel_anchor_y", &Observation::heel_anchor_y)
    .def_ro("t_touchdown", &Observation::t_touchdown);

  nb::class_<Controller, PythonController>(
    m, "Controller",
    "A control law. The controller packages implement it in C++; a Python subclass implements "
    "compute(obs, kinematics) and runs inside the native control loop (docs/usage.md, 'Your "
    "own controller'): it returns the generalized force (18,) [N m, N] of its one source, or a "
    "dict {'effort', 'stiffness', 'damping', 'reference', 'head_target'} (an impedance: all "
    "three gains or none), or {'sources': {name: torque or command}, 'head_target'}; the "
    "attribute 'sources' names its sources (default: its 'name', else its class name). A "
    "wrong answer or an exception in compute is a ControllerError naming it.")
    .def(nb::init<>(), "For a Python subclass (call it from its __init__).")
    .def("compute", &command_values, "obs"_a, "kinematics"_a, kCommandDoc)
    .def("command", &command_values, "obs"_a, "kinematics"_a,
         "As compute of the C++ laws, for every controller (a Python subclass's compute is "
         "its own law): the answer as an EffortCommand carries it, checked.");
}

}  // namespace iceskate_native::bindings
