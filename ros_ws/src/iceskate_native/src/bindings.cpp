// The Python module iceskate_native._kernel: a thin layer of nanobind declarations over the
// C++ API in include/iceskate_native/. No Pinocchio header is included here (only the forward
// declarations behind model.hpp), so this file compiles in seconds; put logic in the core
// library, not here.
//
// Errors: see errors.hpp. std::invalid_argument -> ValueError (nanobind's own translation),
// iceskate_native::NativeError -> iceskate_native.NativeError (a RuntimeError).
#include <cmath>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/map.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include "bindings.hpp"
#include "iceskate_native/binding_parameters.hpp"
#include "iceskate_native/checks.hpp"
#include "iceskate_native/dynamics.hpp"
#include "iceskate_native/errors.hpp"
#include "iceskate_native/guards.hpp"
#include "iceskate_native/integrators.hpp"
#include "iceskate_native/model.hpp"
#include "iceskate_native/observation.hpp"
#include "iceskate_native/simulator.hpp"
#include "iceskate_native/transitions.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace iceskate_native::bindings
{

namespace
{

std::string_view view(const nb::bytes & data) { return {data.c_str(), data.size()}; }

/// (mu, baumgarte, joint_limits, limit_stiffness, limit_damping, damping)
using ParameterRow = std::tuple<double, double, bool, double, double, bool>;
using Optional = std::optional<Eigen::VectorXd>;

/// Construct a Dynamics in place at `self` from the Python-side description of the robot.
void construct_dynamics(
  Dynamics * self, const std::vector<RobotModel> & models, const std::vector<Frames> & frames,
  const std::vector<ModeRow> & modes, const Vector & damping, double total_mass,
  const std::vector<std::tuple<int, double, double>> & limits, const ParameterRow & params)
{
  if (!(total_mass > 0.0) || !std::isfinite(total_mass)) {
    throw std::invalid_argument("total_mass must be a finite mass > 0 kg");
  }
  DynamicsParameters p;
  std::tie(p.mu, p.baumgarte, p.joint_limits, p.limit_stiffness, p.limit_damping, p.damping) =
    params;
  for (double value : {p.mu, p.baumgarte, p.limit_stiffness, p.limit_damping}) {
    if (!std::isfinite(value) || value < 0.0) {
      throw std::invalid_argument(
        "mu, baumgarte, limit_stiffness and limit_damping must be finite and >= 0");
    }
  }
  std::vector<JointLimit> joint_limits;
  for (const auto & [index, lower, upper] : limits) {
    if (!std::isfinite(lower) || !std::isfinite(upper)) {
      throw std::invalid_argument("joint limit " + std::to_string(index) + " is not finite");
    }
    joint_limits.push_back({index, lower, upper});
  }
  new (self) Dynamics(
    support_models(models, frames), mode_table(modes), vector18(damping, "damping"), total_mass,
    std::move(joint_limits), p);
}

Contact contact_of(
  int mode, int side, int pivot, double heel_anchor_y, double support_slide_dir,
  double heel_slide_dir)
{
  for (double value : {heel_anchor_y, support_slide_dir, heel_slide_dir}) {
    if (!std::isfinite(value)) {
      throw std::invalid_argument("the contact's anchor and slide directions must be finite");
    }
  }
  return {mode, side, pivot, heel_anchor_y, support_slide_dir, heel_slide_dir};
}

/// The guards' constants read by name from `constants` (an object with GuardConstants' fields:
/// iceskate_sim.physics.native.GUARD_CONSTANTS); each must be finite.
GuardConstants constants_of(nb::handle constants)
{
  const binding::Fields c(constants, "guard constants: ");
  return {c.number("cop_band"),  c.number("force_band"), c.number("moment_band"),
          c.number("toe_scuff"), c.number("sole_toe_y"), c.number("sole_heel_y")};
}

GuardSet guard_set(
  const std::vector<std::string> & names, const std::vector<double> & rested_until,
  double mu, bool ice, nb::handle constants, double margin)
{
  GuardSet set;
  for (const auto & name : names) {
    set.guards.push_back(guard_named(name));
  }
  if (!rested_until.empty() && rested_until.size() != names.size()) {
    throw std::invalid_argument("rested_until needs one time per guard (or none)");
  }
  set.rested_until = rested_until;
  set.friction = {mu, ice};
  set.constants = constants_of(constants);
  set.margin = margin;
  if (!std::isfinite(mu) || !std::isfinite(margin)) {
    throw std::invalid_argument("the friction coefficient and the guard margin must be finite");
  }
  if (mu < 0.0) {
    throw std::invalid_argument("the friction coefficient mu must be >= 0");
  }
  return set;
}

auto result_tuple(const DynamicsResult & r)
{
  return std::make_tuple(
    Eigen::VectorXd(r.qdd), Eigen::VectorXd(r.multipliers), Eigen::VectorXd(r.support_wrench),
    r.support_normal, r.support_friction, r.zmp_y, r.heel_friction,
    Eigen::VectorXd(r.applied), Eigen::VectorXd(r.swing_heel),
    Eigen::VectorXd(r.swing_heel_velocity), r.swing_toe_z, Eigen::VectorXd(r.passive));
}

Inputs inputs_of(
  const Vector & tau, const Optional & stiffness, const Optional & damping,
  const std::string & push_frame, const Optional & push_force)
{
  Inputs inputs;
  inputs.tau = vector18(tau, "tau");
  if (stiffness.has_value() != damping.has_value()) {
    throw std::invalid_argument("stiffness and damping come together (a joint impedance)");
  }
  if (stiffness) {
    inputs.has_impedance = true;
    inputs.stiffness = vector18(*stiffness, "stiffness");
    inputs.damping = vector18(*damping, "damping");
  }
  if (!push_frame.empty()) {
    if (!push_force) {
      throw std::invalid_argument("a push needs its force");
    }
    require_finite_vector(*push_force, 3, "push_force", "world force [N]");
    inputs.push_frame = push_frame;
    inputs.push_force = *push_force;
  }
  return inputs;
}

/// A state read by name from `state`, an object with the fields of
/// iceskate_sim.physics.hybrid.HybridState (t, q, v, contact, step_index, t_exchange,
/// t_touchdown; the contact's mode (its number), side ('right', 'left'), pivot ('toe', 'heel'),
/// heel_anchor_y, support_slide_dir, heel_slide_dir).
HybridState state_of(nb::handle state)
{
  const binding::Fields s(state, "state: ");
  const binding::Fields c = s.block("contact");
  const double t_touchdown = nb::cast<double>(state.attr("t_touchdown"));
  if (std::isinf(t_touchdown)) {
    throw std::invalid_argument("state: t_touchdown must be finite or NaN (none)");
  }
  const std::vector<double> q = s.numbers("q", kCoordinates), v = s.numbers("v", kCoordinates);
  return {s.number("t"),
          Eigen::Map<const Vector18>(q.data()),
          Eigen::Map<const Vector18>(v.data()),
          {c.block("mode").integer("number", 1),
           c.choice<int>("side", std::array<const char *, 2>{"right", "left"}),
           c.choice<int>("pivot", std::array<const char *, 2>{"toe", "heel"}),
           c.number("heel_anchor_y"), c.number("support_slide_dir"),
           c.number("heel_slide_dir")},
          s.integer("step_index", 0),
          s.number("t_exchange"),
          t_touchdown};
}

/// A state as a dict of HybridState's fields by name, the contact's flattened: t, q, v, mode,
/// side (0 right, 1 left), pivot (0 toe, 1 heel), heel_anchor_y, support_slide_dir,
/// heel_slide_dir, step_index, t_exchange, t_touchdown.
nb::dict state_dict(const HybridState & s)
{
  const auto & c = s.contact;
  nb::dict d;
  d["t"] = s.t;
  d["q"] = Eigen::VectorXd(s.q);
  d["v"] = Eigen::VectorXd(s.v);
  d["mode"] = c.mode;
  d["side"] = c.side;
  d["pivot"] = c.pivot;
  d["heel_anchor_y"] = c.heel_anchor_y;
  d["support_slide_dir"] = c.support_slide_dir;
  d["heel_slide_dir"] = c.heel_slide_dir;
  d["step_index"] = s.step_index;
  d["t_exchange"] = s.t_exchange;
  d["t_touchdown"] = s.t_touchdown;
  return d;
}

/// A HybridSimulator from its settings read by name from `config` (an object with the fields
/// of iceskate_sim.physics.simulation.SimulatorConfig, the one place they are declared, with
/// their defaults), the guards' constants (`constants_of`), margin and table.
void construct_simulator(
  HybridSimulator * self, Dynamics & dynamics, nb::handle initial, nb::handle config,
  nb::handle constants, double margin, const std::vector<std::vector<std::string>> & guards)
{
  if (guards.size() != dynamics.modes().size()) {
    throw std::invalid_argument("the guard table needs the guards of each of the "
                                + std::to_string(dynamics.modes().size()) + " modes");
  }
  const binding::Fields c(config, "simulator settings: ");
  const binding::Fields integrator = c.block("integrator");
  const binding::Fields friction = c.block("friction");
  SimulatorSettings s;
  s.guards.resize(guards.size());
  s.control_period = c.number("control_period");
  s.method = method_named(integrator.text("method"));
  s.step = integrator.number("step");
  s.rtol = integrator.number("rtol");
  s.atol = integrator.number("atol");
  s.event_tolerance = integrator.number("event_tolerance");
  s.projection = integrator.flag("projection");
  const bool ice =
    friction.choice<bool>("rule", std::array<const char *, 2>{"coulomb", "ice"});
  const auto set = guard_set({}, {}, friction.number("mu"), ice, constants, margin);
  s.friction = set.friction;
  s.constants = set.constants;
  s.margin = margin;
  for (std::size_t k = 0; k < guards.size(); ++k) {
    for (const auto & name : guards[k]) {
      s.guards[k].push_back(guard_named(name));
    }
  }
  s.residual_bound = c.number("residual_bound");
  s.fall_height = c.number("fall_height");
  s.max_speed = c.number("max_speed");
  s.max_instant_transitions = c.integer("max_instant_transitions", 1);
  s.zeno_window = c.number("zeno_window");
  s.chatter_dwell = c.number("chatter_dwell");
  new (self) HybridSimulator(dynamics, std::move(s), state_of(initial));
}

/// (t, from_mode, to_mode, event, guard, impulse, step_index, side)
auto record_tuple(const TransitionRecord & r)
{
  return std::make_tuple(r.t, r.from_mode, r.to_mode, r.event, r.guard, r.impulse,
                         r.step_index, r.side);
}

}  // namespace

}  // namespace iceskate_native::bindings

NB_MODULE(_kernel, m)
{
  using namespace iceskate_native;
  using namespace iceskate_native::bindings;
  m.doc() = "Native (C++) kernels of the iceskate simulator on Pinocchio's C++ API.";

  // Translators are tried newest first: the subclasses after their base.
  const auto native_error = nb::exception<NativeError>(m, "NativeError", PyExc_RuntimeError);
  nb::exception<DivergenceError>(m, "DivergenceError", native_error.ptr());
  nb::exception<ChatteringError>(m, "ChatteringError", native_error.ptr());
  bind_controller_error(m, native_error);

  nb::class_<RobotModel>(
    m, "RobotModel",
    "An immutable Pinocchio model on the C++ side, loaded from Pinocchio's binary archive of a "
    "pinocchio.Model (iceskate_native.load_model(model) does both steps).")
    .def_static(
      "from_bytes", [](const nb::bytes & data) { return RobotModel::from_bytes(view(data)); },
      "data"_a,
      "The model from the bytes of model.saveToBinary(pinocchio.serialization.StreamBuffer()) "
      "(iceskate_native.model_bytes); ValueError if they are no such archive.")
    .def_prop_ro("nq", &RobotModel::nq)
    .def_prop_ro("nv", &RobotModel::nv)
    .def_prop_ro("njoints", &RobotModel::njoints)
    .def_prop_ro("name", &RobotModel::name)
    .def("__repr__", [](const RobotModel & model) {
      return "RobotModel(name='" + model.name() + "', nq=" + std::to_string(model.nq())
             + ", nv=" + std::to_string(model.nv()) + ")";
    });

  nb::class_<Dynamics>(
    m, "Dynamics",
    "Eq. (7) of every Table 2 mode on the four support models (index side * 2 + pivot); keeps "
    "Pinocchio workspaces, so one instance per thread.")
    .def(
      "__init__", &construct_dynamics, "models"_a, "frames"_a, "modes"_a, "damping"_a,
      "total_mass"_a, "limits"_a, "params"_a)
    .def(
      "evaluate",
      [](Dynamics & self, int mode, int side, int pivot, double heel_anchor_y,
         double support_slide_dir, double heel_slide_dir, const Vector & q, const Vector & v,
         const Vector & tau, const Optional & stiffness, const Optional & damping,
         const std::string & push_frame, const Optional & push_force) {
        return result_tuple(self.evaluate(
          contact_of(mode, side, pivot, heel_anchor_y, support_slide_dir, heel_slide_dir),
          vector18(q, "q"), vector18(v, "v"),
          inputs_of(tau, stiffness, damping, push_frame, push_force)));
      },
      "mode"_a, "side"_a, "pivot"_a, "heel_anchor_y"_a, "support_slide_dir"_a,
      "heel_slide_dir"_a, "q"_a, "v"_a, "tau"_a, "stiffness"_a = nb::none(),
      "damping"_a = nb::none(), "push_frame"_a = "", "push_force"_a = nb::none(),
      "Eq. (7) at (q, v): (qdd, multipliers, support_wrench, support_normal, "
      "support_friction, zmp_y, heel_friction, applied, swing_heel, swing_heel_velocity, "
      "swing_toe_z, passive). ValueError for bad input, NativeError for a rank-deficient or "
      "singular system.")
    .def(
      "linearize",
      [](Dynamics & self, int mode, int side, int pivot, double heel_anchor_y,
         double support_slide_dir, double heel_slide_dir, const Vector & q, const Vector & v,
         const Vector & tau, const Optional & stiffness, const Optional & damping,
         const std::string & push_frame, const Optional & push_force, double lookahead) {
        if (!(lookahead >= 0.0) || !std::isfinite(lookahead)) {
          throw std::invalid_argument("lookahead must be a finite time >= 0 s");
        }
        const LinearizedSystem & system = self.linearize(
          contact_of(mode, side, pivot, heel_anchor_y, support_slide_dir, heel_slide_dir),
          vector18(q, "q"), vector18(v, "v"),
          inputs_of(tau, stiffness, damping, push_frame, push_force), lookahead);
        return std::make_tuple(Eigen::MatrixXd(system.matrix), system.n, system.nc,
                               Eigen::VectorXd(system.stiffness), Eigen::VectorXd(system.damping));
      },
      "mode"_a, "side"_a, "pivot"_a, "heel_anchor_y"_a, "support_slide_dir"_a,
      "heel_slide_dir"_a, "q"_a, "v"_a, "tau"_a, "stiffness"_a = nb::none(),
      "damping"_a = nb::none(), "push_frame"_a = "", "push_force"_a = nb::none(),
      "lookahead"_a = 0.0,
      "Eq. (7) at (q, v) as a linear system in (qdd over the n active coordinates, the nc "
      "multipliers): (matrix (n + nc square), n, nc, stiffness, damping), the held stiffness "
      "and damping per coordinate (soft stops past which q or q + lookahead v is).")
    .def(
      "implicit_acceleration",
      [](Dynamics & self, int mode, int side, int pivot, double heel_anchor_y,
         double support_slide_dir, double heel_slide_dir, const Vector & q, const Vector & v,
         const Vector & tau, const Optional & stiffness, const Optional & damping,
         const std::string & push_frame, const Optional & push_force, double step) {
        return Eigen::VectorXd(self.implicit_acceleration(
          contact_of(mode, side, pivot, heel_anchor_y, support_slide_dir, heel_slide_dir),
          vector18(q, "q"), vector18(v, "v"),
          inputs_of(tau, stiffness, damping, push_frame, push_force), step));
      },
      "mode"_a, "side"_a, "pivot"_a, "heel_anchor_y"_a, "support_slide_dir"_a,
      "heel_slide_dir"_a, "q"_a, "v"_a, "tau"_a, "stiffness"_a, "damping"_a, "push_frame"_a,
      "push_force"_a, "step"_a,
      "Accelerations (18,) of an implicit step of size step [s]: (M + h D) a = f - D v.")
    .def(
      "guard_values",
      [](Dynamics & self, int mode, int side, int pivot, double heel_anchor_y,
         double support_slide_dir, double heel_slide_dir, const Vector & q, const Vector & v,
         const Vector & tau, const Optional & stiffness, const Optional & damping,
         const std::string & push_frame, const Optional & push_force,
         const std::vector<std::string> & guards, const std::vector<double> & rested_until,
         double mu, bool ice, nb::handle constants, double margin, double t) {
        const auto contact =
          contact_of(mode, side, pivot, heel_anchor_y, support_slide_dir, heel_slide_dir);
        const Vector18 q18 = vector18(q, "q"), v18 = vector18(v, "v");
        const auto result = self.evaluate(
          contact, q18, v18, inputs_of(tau, stiffness, damping, push_frame, push_force));
        State x;
        x << q18, v18;
        return guard_values(
          guard_set(guards, rested_until, mu, ice, constants, margin), contact, t, x, result);
      },
      "mode"_a, "side"_a, "pivot"_a, "heel_anchor_y"_a, "support_slide_dir"_a,
      "heel_slide_dir"_a, "q"_a, "v"_a, "tau"_a, "stiffness"_a, "damping"_a, "push_frame"_a,
      "push_force"_a, "guards"_a, "rested_until"_a, "mu"_a, "ice"_a, "constants"_a, "margin"_a,
      "t"_a,
      "The values of the named guards (E1..S7) at (q, v) under the inputs (rested ones -1).")
    .def(
      "integrate_segment",
      [](Dynamics & self, int mode, int side, int pivot, double heel_anchor_y,
         double support_slide_dir, double heel_slide_dir, const Vector & tau,
         const Optional & stiffness, const Optional & damping, const std::string & push_frame,
         const Optional & push_force, const std::string & method, double step, double rtol,
         double atol, double event_tolerance, const std::vector<std::string> & guards,
         const std::vector<double> & rested_until, double mu, bool ice,
         nb::handle constants, double margin, double t0, const Vector & x0,
         double t_end) {
        const auto contact =
          contact_of(mode, side, pivot, heel_anchor_y, support_slide_dir, heel_slide_dir);
        require_finite_vector(x0, 2 * kCoordinates, "x0", "[q, v]");
        const State x = x0;
        const auto inputs = inputs_of(tau, stiffness, damping, push_frame, push_force);
        const auto start =
          self.evaluate(contact, x.head<kCoordinates>(), x.tail<kCoordinates>(), inputs);
        const auto kind = method_named(method);
        const auto set = guard_set(guards, rested_until, mu, ice, constants, margin);
        double first_step = step;
        const auto segment =
          kind == Method::kRk45
            ? integrate_adaptive(
                self, contact, inputs, {rtol, atol, step}, event_tolerance, set, t0, x, t_end,
                start, first_step)
          : kind == Method::kRos34pw2
            ? integrate_rosenbrock(
                self, contact, inputs, {rtol, atol, step}, event_tolerance, set, t0, x, t_end,
                start, first_step)
            : integrate_fixed(
                self, contact, inputs, kind, step, event_tolerance, set, t0, x, t_end, start);
        return std::make_tuple(
          segment.t, Eigen::VectorXd(segment.x), result_tuple(segment.result), segment.fired,
          segment.steps, segment.evaluations + 1);
      },
      "mode"_a, "side"_a, "pivot"_a, "heel_anchor_y"_a, "support_slide_dir"_a,
      "heel_slide_dir"_a, "tau"_a, "stiffness"_a, "damping"_a, "push_frame"_a, "push_force"_a,
      "method"_a, "step"_a, "rtol"_a, "atol"_a, "event_tolerance"_a, "guards"_a,
      "rested_until"_a, "mu"_a, "ice"_a, "constants"_a, "margin"_a, "t0"_a, "x0"_a, "t_end"_a,
      "Integrate from (t0, x0) to t_end or the first crossing of one of the named guards "
      "(located to event_tolerance [s]) with a fixed-step method (step [s]) or an adaptive one, "
      "rk45 or ros34pw2 (rtol, atol; step: its first and largest step [s]): (t, x, dynamics tuple as evaluate's, index "
      "of the guard that fired or -1, steps, evaluations).");

  nb::class_<HybridSimulator>(
    m, "HybridSimulator",
    "Whole control periods of the hybrid simulation on a Dynamics kernel (kept alive by it): "
    "integration (fixed-step, rk45 or ros34pw2) with event location, transitions, projection and health "
    "checks. A state goes in read by name from an object with the fields of "
    "iceskate_sim.physics.hybrid.HybridState and comes out as a dict of them (`state`).")
    .def(
      "__init__", &construct_simulator, "dynamics"_a, "initial"_a, "config"_a, "constants"_a,
      "margin"_a, "guards"_a, nb::keep_alive<1, 2>(),
      "dynamics: the Dynamics kernel; initial: the initial state (read by name); config: the run's settings, read "
      "by name (iceskate_sim.physics.simulation.SimulatorConfig: control_period, integrator "
      "(method, step, rtol, atol, event_tolerance, projection), friction (mu, rule), "
      "residual_bound, fall_height, max_speed, max_instant_transitions, zeno_window, "
      "chatter_dwell); constants: the guards' dead bands and sole geometry, read by name "
      "(GuardConstants' fields); margin: a guard at most this positive is not due; guards: the "
      "guard names of each mode. ValueError naming a field that is missing or bad.")
    .def("reset", &HybridSimulator::reset, "Back to the initial state; clears log and counters.")
    .def(
      "set_state",
      [](HybridSimulator & self, nb::handle state) { self.set_state(state_of(state)); },
      "state"_a,
      "Continue from `state` (the event log, counters and rested guards kept; an ended run goes "
      "on).")
    .def(
      "advance",
      [](HybridSimulator & self, const Vector & tau, const Optional & stiffness,
         const Optional & damping, const std::string & push_frame, const Optional & push_force) {
        self.advance(inputs_of(tau, stiffness, damping, push_frame, push_force));
      },
      "tau"_a, "stiffness"_a = nb::none(), "damping"_a = nb::none(), "push_frame"_a = "",
      "push_force"_a = nb::none(),
      "One control period holding the inputs. ValueError for bad input or an ended run; "
      "DivergenceError, ChatteringError or NativeError when the physics fails (the state is "
      "where it failed).")
    .def_prop_ro(
      "state", [](const HybridSimulator & self) { return state_dict(self.state()); },
      "The current state, a dict of HybridState's fields by name (the contact's flattened: "
      "mode, side 0 right / 1 left, pivot 0 toe / 1 heel, heel_anchor_y, support_slide_dir, "
      "heel_slide_dir).")
    .def(
      "observation",
      [](HybridSimulator & self) {
        const HybridState & s = self.state();
        return observation_of(s, self.dynamics().mode(s.contact.mode));
      },
      "The controllers' Observation of the current state, as the control loop gives it to "
      "them: times at a stamp's resolution (whole ns), the pivot toe (0) while the sole is "
      "flat.")
    .def_prop_ro(
      "start_state", [](const HybridSimulator & self) { return state_dict(self.start_state()); },
      "The state the last period started from, as `state`.")
    .def_prop_ro(
      "start_result",
      [](const HybridSimulator & self) { return result_tuple(self.start_result()); })
    .def_prop_ro("result", [](const HybridSimulator & self) { return result_tuple(self.result()); })
    .def(
      "events_since",
      [](const HybridSimulator & self, std::size_t first) {
        const auto & events = self.events();
        std::vector<decltype(record_tuple(events.front()))> out;
        for (std::size_t i = first; i < events.size(); ++i) {
          out.push_back(record_tuple(events[i]));
        }
        return out;
      },
      "first"_a,
      "Events from index `first` on: (t, from_mode, to_mode, event, guard, impulse, "
      "step_index, side).")
    .def_prop_ro(
      "statistics",
      [](const HybridSimulator & self) {
        const auto & s = self.statistics();
        return std::make_tuple(s.steps, s.evaluations, s.control_periods,
                               s.max_constraint_residual, s.max_constraint_drift,
                               s.suppressed_cycles, s.resolved_cycles);
      },
      "(steps, evaluations, control_periods, max_constraint_residual, max_constraint_drift, "
      "suppressed_cycles, resolved_cycles)")
    .def_prop_ro(
      "ended", [](const HybridSimulator & self) { return static_cast<int>(self.ended()); },
      "0 running, 1 flight, 2 toe-first touchdown, 3 fall.");

  bind_controller(m);
  bind_cdr(m);
  bind_control_loop(m);
}
