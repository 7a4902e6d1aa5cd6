// Bindings of the control loop (control_loop.hpp), part of iceskate_native._kernel: a
// ControlLoop over a HybridSimulator, a Kinematics and native Controller objects, which it keeps
// alive, or over the commands of controller nodes it receives (see the bound docstrings).
#include <algorithm>
#include <cstdint>
#include <exception>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/pair.h>
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
  SampleBlock live;                    ///< the live view (live_fill)
  std::vector<ReceivedCommand> inbox;  ///< one per controller node of `receive`
  std::vector<bool> received;          ///< inbox[k] holds a command
  std::vector<ReceivedCommand> held;   ///< the received ones of a period, in order
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
  const Vector & head_origin,
  const std::vector<std::pair<std::string, std::string>> & tf_pairs,
  const std::vector<std::vector<std::string>> & inbox)
{
  HybridSimulator & sim = native_object<HybridSimulator>(simulator, "the simulator");
  Kinematics * kin =
    kinematics.is_none() ? nullptr : &native_object<Kinematics>(kinematics, "the kinematics");
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
  std::vector<ReceivedCommand> slots(inbox.size());
  for (std::size_t k = 0; k < inbox.size(); ++k) {
    slots[k].sources = inbox[k];
  }
  new (self) BoundControlLoop{
    std::move(simulator), std::move(kinematics), std::move(controllers),
    ControlLoop(sim, kin, std::move(laws), std::move(rows), head_origin, tf_pairs),
    SampleBlock{}, SampleBlock{}, std::move(slots), std::vector<bool>(inbox.size(), false), {}};
}

/// Store controller node `index`'s command (see bind_control_loop for the arguments).
void receive(
  BoundControlLoop & self, std::size_t index, const Vector & effort, const Vector & stiffness,
  const Vector & damping, const Vector & reference, const Vector & source_efforts,
  const Vector & head_target)
{
  if (index >= self.inbox.size()) {
    throw std::invalid_argument(
      "controller index " + std::to_string(index) + " is not below the "
      + std::to_string(self.inbox.size()) + " controller nodes of the loop");
  }
  ReceivedCommand & command = self.inbox[index];
  const auto sources = static_cast<Eigen::Index>(command.sources.size());
  const char * joints = "[y0, q1..q17]";
  require_finite_vector(effort, kCoordinates, "effort", joints);
  const bool impedance = stiffness.size() + damping.size() + reference.size() > 0;
  if (impedance) {
    require_finite_vector(stiffness, kCoordinates, "stiffness", joints);
    require_finite_vector(damping, kCoordinates, "damping", joints);
    require_finite_vector(reference, kCoordinates, "position_reference", joints);
    if (stiffness.minCoeff() < 0.0 || damping.minCoeff() < 0.0) {
      throw std::invalid_argument("stiffness and damping must be >= 0");
    }
  }
  require_finite_vector(
    source_efforts, sources * kCoordinates, "source_efforts", "18 per source, in order");
  if (head_target.size() != 0) {
    require_finite_vector(head_target, 3, "head_target", "y [m], z [m], pitch [rad]");
  }
  command.total.effort = effort;
  command.total.has_impedance = impedance;
  if (impedance) {
    command.total.stiffness = stiffness;
    command.total.damping = damping;
    command.total.reference = reference;
  }
  command.efforts = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, kCoordinates,
                                                   Eigen::RowMajor>>(source_efforts.data(),
                                                                     sources, kCoordinates);
  command.has_head_target = head_target.size() != 0;
  if (command.has_head_target) {
    command.head_target = head_target;
  }
  self.received[index] = true;
}

bool hold(BoundControlLoop & self, bool clear)
{
  // every node answered (lockstep): the inbox as it is; else a copy of the commands received
  const bool all =
    std::all_of(self.received.begin(), self.received.end(), [](bool got) { return got; });
  if (!all) {
    self.held.clear();
    for (std::size_t k = 0; k < self.inbox.size(); ++k) {
      if (self.received[k]) {
        self.held.push_back(self.inbox[k]);
      }
    }
  }
  bool taken = false;
  {
    nb::gil_scoped_release released;
    taken = self.loop.hold(all ? self.inbox : self.held, self.block);
  }
  if (clear) {
    std::fill(self.received.begin(), self.received.end(), false);
  }
  return taken;
}

/// A numpy array that takes over `data` (no copy): (rows,) for width 1, else (rows, width).
template <typename T>
nb::object array_of(std::vector<T> && data, std::size_t rows, std::size_t width)
{
  auto * owner = new std::vector<T>(std::move(data));
  nb::capsule deleter(owner, [](void * p) noexcept { delete static_cast<std::vector<T> *>(p); });
  const std::size_t shape[2] = {rows, width};
  return nb::cast(nb::ndarray<nb::numpy, T>(owner->data(), width == 1 ? 1 : 2, shape, deleter));
}

/// The samples of `b` as numpy arrays (taken over: `b` is left empty, its sources kept).
nb::dict block_arrays(SampleBlock & b)
{
  const auto n = static_cast<std::size_t>(b.count);
  nb::dict out;
  for_each_column(b, [&](const char * key, auto & column, std::size_t width) {
    out[key] = array_of(std::move(column), n, width);
  });
  nb::list sources;
  nb::list efforts;
  for (std::size_t i = 0; i < b.sources.size(); ++i) {
    sources.append(b.sources[i]);
    efforts.append(array_of(std::move(b.efforts[i]), n, kCoordinates));
  }
  out["sources"] = sources;
  out["efforts"] = efforts;
  b.clear();
  return out;
}

nb::dict run(BoundControlLoop & self, int periods)
{
  if (periods < 0) {
    throw std::invalid_argument("the number of periods must be >= 0");
  }
  {
    // The loop touches no Python object (a controller written in Python takes the GIL for its
    // own call): other Python threads, e.g. the one that hands the bag's samples to its
    // writer, run.
    nb::gil_scoped_release released;
    self.loop.run(periods, self.block);
  }
  return block_arrays(self.block);
}

nb::dict live(BoundControlLoop & self)
{
  SampleBlock sample;
  self.loop.live(sample);
  return block_arrays(sample);
}

std::tuple<int, std::int64_t, std::uint64_t> live_fill(BoundControlLoop & self)
{
  self.loop.live(self.live);
  return {self.live.mode[0], self.live.last_event[0], self.live.present[0]};
}

nb::list live_messages(const BoundControlLoop & self, const std::vector<std::string> & names,
                       const std::vector<const CdrProgram *> & programs)
{
  if (self.live.count != 1) {
    throw std::invalid_argument("live_messages() needs live_fill() first");
  }
  std::vector<Column> columns;
  columns.reserve(names.size());
  for (const auto & name : names) {
    columns.push_back(column_of(self.live, name));
  }
  nb::list out;
  for (const CdrProgram * program : programs) {
    program->check(columns);
    nb::bytes data(nullptr, program->size());
    program->write(columns, 0, static_cast<std::uint8_t *>(
                                 static_cast<void *>(const_cast<char *>(data.c_str()))));
    out.append(data);
  }
  return out;
}

/// numpy's name of the dtype of a column of T.
template <class T>
const char * dtype_name(const std::vector<T> &)
{
  switch (column_type(std::vector<T>{})) {
    case Column::Type::kFloat64: return "float64";
    case Column::Type::kInt64: return "int64";
    case Column::Type::kInt32: return "int32";
    case Column::Type::kUint64: return "uint64";
    case Column::Type::kUint8: return "uint8";
  }
  return "";
}

/// ICESKATE_SAMPLE_COLUMNS as a tuple of (name, dtype, width (0: kTfPoseWidth per /tf pair),
/// unit, saved, routes, meaning).
nb::tuple sample_columns()
{
  nb::list out;
#define ICESKATE_SAMPLE_ROW(name, type, width, unit, saved, routes, meaning) \
  out.append(nb::make_tuple(#name, dtype_name(std::vector<type>{}),        \
                            static_cast<std::size_t>(width), unit, saved, routes, meaning));
  ICESKATE_SAMPLE_COLUMNS(ICESKATE_SAMPLE_ROW)
#undef ICESKATE_SAMPLE_ROW
  return nb::tuple(out);
}

}  // namespace

void bind_control_loop(nb::module_ & m)
{
  m.attr("SAMPLE_COLUMNS_TABLE") = sample_columns();
  m.attr("TF_POSE_WIDTH") = kTfPoseWidth;
  nb::class_<BoundControlLoop>(
    m, "ControlLoop",
    "Many control periods in one call: the controllers (native Controller objects, in summing "
    "order) answer the observation of each control instant through the kinematics, their "
    "commands' sum and the active push are held over the period, the simulator advances. It "
    "keeps the simulator, kinematics and controllers alive.")
    .def(
      "__init__", &construct_loop, "simulator"_a, "kinematics"_a.none(), "controllers"_a,
      "pushes"_a, "head_origin"_a, "tf_pairs"_a,
      "inbox"_a = std::vector<std::vector<std::string>>{},
      "simulator: a HybridSimulator; kinematics: a Kinematics (None without controllers); "
      "controllers: Controller objects; pushes: [(start [s], duration [s], frame, world force "
      "(3,) [N])]; head_origin: the head target recorded while no controller steers one; "
      "tf_pairs: the (parent, child) link frames whose /tf transform a sample records, parent "
      "'world' for the world frame; "
      "inbox: the source names of each controller node whose commands come through receive(), "
      "in summing order.")
    .def(
      "receive", &receive, "index"_a, "effort"_a, "stiffness"_a, "damping"_a, "reference"_a,
      "source_efforts"_a, "head_target"_a,
      "Keep the command of controller node `index` of the inbox for the next hold(), as an "
      "EffortCommand carries it: effort (18,); stiffness, damping, reference (18,) each, or all "
      "three empty (no impedance); source_efforts: 18 per source of the node, in order, flat; "
      "head_target (3,) or empty. ValueError for a wrong size, a non-finite value or a "
      "negative gain (the command is then not kept).")
    .def(
      "hold", &hold, "clear"_a = true,
      "One control period holding the sum of the commands received (in the inbox's order) and "
      "the active push; its sample is appended to the block (take_block). Returns False if the "
      "physics failed (raise_error() raises why). clear: forget the commands afterwards (else "
      "they are held again until replaced).")
    .def(
      "forget",
      [](BoundControlLoop & self) {
        std::fill(self.received.begin(), self.received.end(), false);
      },
      "Drop the commands received (hold() then holds none until the next receive()).")
    .def(
      "live_fill", &live_fill,
      "Take the live view of the current state (live()'s sample) for live_messages(); returns "
      "its (mode, last_event, present).")
    .def(
      "live_messages", &live_messages, "columns"_a, "programs"_a,
      "The bytes of one message per CdrProgram, of the sample live_fill() took; the programs' "
      "slots number the `columns` (take_block()'s keys, 'efforts.<i>' for source i's). "
      "ValueError for an unknown column or one a slot reads beyond.")
    .def(
      "take_block", [](BoundControlLoop & self) { return block_arrays(self.block); },
      "The samples held since the last take_block, as run() returns them; the block is emptied.")
    .def_prop_ro(
      "block_size", [](const BoundControlLoop & self) { return self.block.count; },
      "Samples held and not taken yet.")
    .def(
      "live", &live,
      "The live view of the current state, what the simulator publishes before the commands "
      "of t_k exist: one sample as take_block() returns it (the same keys, one row): the "
      "state, its dynamics under the inputs held over the last period, the held input's "
      "generalized force at the state as the one source 'held' and that period's head "
      "target.")
    .def(
      "run", &run, "periods"_a,
      "Up to `periods` control periods; returns their samples as a dict of numpy arrays: the "
      "columns of SAMPLE_COLUMNS ((n,) for one value per sample, else (n, width)), sources "
      "(names) and efforts (one (n, 18) array per source). It stops after a period that ends "
      "the run, and before a period that "
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
