// Bindings of the control loop (control_loop.hpp), part of iceskate_native._kernel: a
// ControlLoop over a HybridSimulator, a Kinematics and the controllers (native Controller
// objects, e.g. visual_lifting._law.VisualLiftingController), which it keeps alive; run(n)
// returns the samples of up to n periods as numpy arrays, and raise_error() re-raises what
// stopped it early (the simulator's DivergenceError & co. or the controller's own error).
#include <cstdint>
#include <exception>
#include <initializer_list>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include "bindings.hpp"
#include "iceskate_native/checks.hpp"
#include "iceskate_native/control_loop.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace iceskate_native::bindings
{

namespace
{

/// A ControlLoop and the Python objects it refers to (kept alive as long as it lives).
struct BoundControlLoop
{
  nb::object simulator;
  nb::object kinematics;
  std::vector<nb::object> controllers;
  ControlLoop loop;
  SampleBlock block;
};

/// The C++ object behind `object`; std::invalid_argument naming `what` if it is no T.
template <typename T>
T & native_object(const nb::object & object, const char * what)
{
  T * native = nullptr;
  if (!nb::try_cast<T *>(object, native) || native == nullptr) {
    throw std::invalid_argument(
      std::string(what) + " is a " + nb::type_name(object.type()).c_str() + ", not an "
      + "iceskate_native." + nb::type_name(nb::type<T>()).c_str());
  }
  return *native;
}

/// (start [s], duration [s], frame, world force [N])
using PushRow = std::tuple<double, double, std::string, Eigen::VectorXd>;

void construct_loop(
  BoundControlLoop * self, nb::object simulator, nb::object kinematics,
  std::vector<nb::object> controllers, const std::vector<PushRow> & pushes,
  const Eigen::Ref<const Eigen::VectorXd> & head_origin)
{
  HybridSimulator & sim = native_object<HybridSimulator>(simulator, "the simulator");
  Kinematics & kin = native_object<Kinematics>(kinematics, "the kinematics");
  std::vector<Controller *> laws;
  for (std::size_t k = 0; k < controllers.size(); ++k) {
    laws.push_back(
      &native_object<Controller>(controllers[k], ("controller " + std::to_string(k)).c_str()));
  }
  std::vector<Push> rows;
  for (const auto & [start, duration, frame, force] : pushes) {
    require_finite_vector(force, 3, "push force", "world force [N]");
    rows.push_back({start, duration, frame, force});
  }
  require_finite_vector(head_origin, 3, "head_origin", "psi: y [m], z [m], pitch [rad]");
  new (self) BoundControlLoop{
    std::move(simulator), std::move(kinematics), std::move(controllers),
    ControlLoop(sim, kin, std::move(laws), std::move(rows), head_origin), SampleBlock{}};
}

/// A numpy array that takes over `data` (no copy), of the given shape.
template <typename T>
nb::object array_of(std::vector<T> && data, std::initializer_list<std::size_t> shape)
{
  auto * owner = new std::vector<T>(std::move(data));
  nb::capsule deleter(owner, [](void * p) noexcept { delete static_cast<std::vector<T> *>(p); });
  return nb::cast(nb::ndarray<nb::numpy, T>(owner->data(), shape, deleter));
}

nb::dict run(BoundControlLoop & self, int periods)
{
  if (periods < 0) {
    throw std::invalid_argument("the number of periods must be >= 0");
  }
  SampleBlock & b = self.block;
  int taken = 0;
  {
    // The loop touches no Python object (the controllers are C++ ones, checked when bound):
    // other Python threads, e.g. the one that hands the bag's samples to its writer, run.
    nb::gil_scoped_release released;
    taken = self.loop.run(periods, b);
  }
  const auto n = static_cast<std::size_t>(taken);
  constexpr std::size_t m = kCoordinates;
  nb::dict out;
  out["t"] = array_of(std::move(b.t), {n});
  out["t_exchange"] = array_of(std::move(b.t_exchange), {n});
  out["t_touchdown"] = array_of(std::move(b.t_touchdown), {n});
  out["heel_anchor_y"] = array_of(std::move(b.heel_anchor_y), {n});
  out["mode"] = array_of(std::move(b.mode), {n});
  out["side"] = array_of(std::move(b.side), {n});
  out["pivot"] = array_of(std::move(b.pivot), {n});
  out["step_index"] = array_of(std::move(b.step_index), {n});
  out["q"] = array_of(std::move(b.q), {n, m});
  out["v"] = array_of(std::move(b.v), {n, m});
  out["qdd"] = array_of(std::move(b.qdd), {n, m});
  out["passive"] = array_of(std::move(b.passive), {n, m});
  out["applied"] = array_of(std::move(b.applied), {n, m});
  out["multipliers"] = array_of(std::move(b.multipliers), {n, 3});
  out["support_normal"] = array_of(std::move(b.support_normal), {n});
  out["support_tangential"] = array_of(std::move(b.support_tangential), {n});
  out["cop_y"] = array_of(std::move(b.cop_y), {n});
  out["head_position"] = array_of(std::move(b.head_position), {n, 3});
  out["head_rotation"] = array_of(std::move(b.head_rotation), {n, 3, 3});
  out["head_target"] = array_of(std::move(b.head_target), {n, 3});
  out["last_event"] = array_of(std::move(b.last_event), {n});
  out["present"] = array_of(std::move(b.present), {n});
  nb::list sources;
  nb::list efforts;
  for (std::size_t i = 0; i < b.sources.size(); ++i) {
    sources.append(b.sources[i]);
    efforts.append(array_of(std::move(b.efforts[i]), {n, m}));
  }
  out["sources"] = sources;
  out["efforts"] = efforts;
  return out;
}

}  // namespace

void bind_control_loop(nb::module_ & m)
{
  nb::class_<BoundControlLoop>(
    m, "ControlLoop",
    "Many control periods in one call: the controllers (native Controller objects, in summing "
    "order) answer the observation of each control instant through the kinematics, their "
    "commands' sum and the active push are held over the period, the simulator advances. It "
    "keeps the simulator, kinematics and controllers alive.")
    .def(
      "__init__", &construct_loop, "simulator"_a, "kinematics"_a, "controllers"_a, "pushes"_a,
      "head_origin"_a,
      "simulator: a HybridSimulator; kinematics: a Kinematics; controllers: Controller "
      "objects; pushes: [(start [s], duration [s], frame, world force (3,) [N])]; "
      "head_origin: the head target recorded while no controller steers one.")
    .def(
      "run", &run, "periods"_a,
      "Up to `periods` control periods; returns their samples as a dict of numpy arrays (t, "
      "t_exchange, t_touchdown, heel_anchor_y, mode, side, pivot, step_index, q, v, qdd, "
      "passive, applied, multipliers, support_normal, support_tangential, cop_y, "
      "head_position, head_rotation, head_target, last_event (index in the event log, -1: "
      "none), present (bit i: source i answered), sources (names), efforts (one (n, 18) array "
      "per source)). It stops after a period that ends the run, and before a period that "
      "failed: `failed` is then True and raise_error() raises the failure.")
    .def_prop_ro(
      "failed", [](const BoundControlLoop & self) { return self.loop.error() != nullptr; },
      "Whether the last run stopped on an error.")
    .def_prop_ro(
      "physics_failed", [](const BoundControlLoop & self) { return self.loop.physics_failed(); },
      "Whether that error came from the simulator's period (else from a controller).")
    .def(
      "raise_error",
      [](const BoundControlLoop & self) {
        if (self.loop.error() != nullptr) {
          std::rethrow_exception(self.loop.error());
        }
      },
      "Raise what stopped the last run (nothing if it did not fail).");
}

}  // namespace iceskate_native::bindings
