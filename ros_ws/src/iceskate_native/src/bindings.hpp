// What the translation units of the module iceskate_native._kernel share (private: not
// installed): the checks of array arguments, the Python-side description of the mode table and
// the support models, and the entry points of the other bindings, called from bindings.cpp.
#pragma once

#include <algorithm>
#include <array>
#include <map>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include <nanobind/nanobind.h>

#include "iceskate_native/checks.hpp"
#include "iceskate_native/dynamics.hpp"
#include "iceskate_native/modes.hpp"

namespace iceskate_native::bindings
{

/// (number, y0_active, q1_active, swing_sliding, active coordinates, constraint names)
using ModeRow = std::tuple<int, bool, bool, bool, std::vector<int>, std::vector<std::string>>;
/// A read-only array argument of doubles.
using Vector = Eigen::Ref<const Eigen::VectorXd>;
/// Frame name -> index of one support model.
using Frames = std::map<std::string, int>;

/// The mode table of the rows of iceskate_sim.model.modes.MODES (checked by the kernel that
/// takes it, check_modes); std::invalid_argument for an unknown constraint.
inline ModeTable mode_table(const std::vector<ModeRow> & rows)
{
  ModeTable table(rows.size());
  for (std::size_t k = 0; k < rows.size(); ++k) {
    auto & mode = table[k];
    std::vector<std::string> names;
    std::tie(mode.number, mode.y0_active, mode.q1_active, mode.swing_sliding, mode.active,
             names) = rows[k];
    for (const auto & name : names) {
      constexpr std::array<const char *, 3> codes = {"hz", "hy", "fr"};  // Constraint's order
      const auto code = std::find(codes.begin(), codes.end(), name);
      if (code == codes.end()) {
        throw std::invalid_argument("unknown swing constraint '" + name + "' (hz, hy or fr)");
      }
      mode.constraints.push_back(static_cast<Constraint>(code - codes.begin()));
    }
  }
  return table;
}

/// `value` as the 18 finite entries of [y0, q1..q17]; std::invalid_argument naming `name`.
inline Vector18 vector18(const Vector & value, const char * name)
{
  require_finite_vector(value, kCoordinates, name, "[y0, q1..q17]");
  return value;
}

/// The four support models (index side * 2 + pivot) with their frames; std::invalid_argument
/// for another number.
inline std::array<SupportModel, 4> support_models(
  const std::vector<RobotModel> & models, const std::vector<Frames> & frames)
{
  if (models.size() != 4 || frames.size() != 4) {
    throw std::invalid_argument(
      "four support models (index side * 2 + pivot) and their frames are needed");
  }
  return {SupportModel{models[0], frames[0]}, SupportModel{models[1], frames[1]},
          SupportModel{models[2], frames[2]}, SupportModel{models[3], frames[3]}};
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
