// What the translation units of the module iceskate_native._kernel share (private: not
// installed): the Python-side description of the mode table, and the entry point of the
// controller interface's bindings (bindings_controller.cpp, python_controller.cpp) and of the
// control loop (bindings_loop.cpp), called from bindings.cpp.
#pragma once

#include <map>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include <nanobind/nanobind.h>

#include "iceskate_native/modes.hpp"

namespace iceskate_native::bindings
{

/// (number, y0_active, q1_active, swing_sliding, active coordinates, constraint names)
using ModeRow = std::tuple<int, bool, bool, bool, std::vector<int>, std::vector<std::string>>;
/// Frame name -> index of one support model.
using Frames = std::map<std::string, int>;

/// The mode table of the 20 rows of iceskate_sim.model.modes.MODES; std::invalid_argument otherwise.
inline ModeTable mode_table(const std::vector<ModeRow> & rows)
{
  if (rows.size() != kModes) {
    throw std::invalid_argument("the mode table needs the 20 modes of Table 2, got "
                                + std::to_string(rows.size()));
  }
  ModeTable table;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    auto & mode = table[k];
    std::vector<std::string> names;
    std::tie(mode.number, mode.y0_active, mode.q1_active, mode.swing_sliding, mode.active,
             names) = rows[k];
    for (const auto & name : names) {
      if (name == "hz") {
        mode.constraints.push_back(Constraint::kHeelZ);
      } else if (name == "hy") {
        mode.constraints.push_back(Constraint::kHeelY);
      } else if (name == "fr") {
        mode.constraints.push_back(Constraint::kSoleFlat);
      } else {
        throw std::invalid_argument("unknown swing constraint '" + name + "' (hz, hy or fr)");
      }
    }
  }
  return table;
}

/// Kinematics, ModelKinematics, Observation and Controller in module `m`.
void bind_controller(nanobind::module_ & m);

/// iceskate_native.ControllerError (a kind of `native_error`) in module `m`: what a controller
/// written in Python raises when it fails (python_controller.cpp).
void bind_controller_error(nanobind::module_ & m, nanobind::handle native_error);

/// CdrProgram and encode_rows in module `m` (bindings_cdr.cpp).
void bind_cdr(nanobind::module_ & m);

/// ControlLoop in module `m` (after HybridSimulator, Kinematics, Controller and CdrProgram).
void bind_control_loop(nanobind::module_ & m);

}  // namespace iceskate_native::bindings
