// The module gait_manager._law: GaitManagerController, the C++ sources as an
// iceskate_native.Controller (the base type comes from iceskate_native, imported first), built
// from a GaitManagerParameters object (the one schema): read_gait_manager, generated from
// gait_manager/parameters.py, reads every field by its name; a bad field is a ValueError naming
// it, a command that is not finite a gait_manager.errors.GaitManagerError.
#include <exception>

#include <nanobind/nanobind.h>
#include <nanobind/stl/optional.h>

#include "gait_manager/errors.hpp"
#include "gait_manager/law.hpp"
#include "gait_manager/parameter_readers.hpp"
#include "iceskate_native/binding_parameters.hpp"
#include "iceskate_native/controller.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace
{

gait_manager::GaitManagerParameters parameters_of(nb::handle object)
{
  return gait_manager::read_gait_manager(iceskate_native::binding::Fields(object));
}

}  // namespace

NB_MODULE(_law, m)
{
  m.doc() = "The gait-manager sources in C++ as an iceskate_native.Controller.";
  nb::module_::import_("iceskate_native");  // registers the base type Controller
  const nb::object error = nb::module_::import_("gait_manager.errors").attr("GaitManagerError");
  nb::register_exception_translator(
    [](const std::exception_ptr & p, void * payload) {
      try {
        std::rethrow_exception(p);
      } catch (const gait_manager::GaitManagerError & e) {
        PyErr_SetString(static_cast<PyObject *>(payload), e.what());
      }
    },
    error.inc_ref().ptr());

  using gait_manager::GaitManagerController;
  nb::class_<GaitManagerController, iceskate_native::Controller>(
    m, "GaitManagerController",
    "The enabled gait-manager sources (posture, feedforward, weight_transfer, heel, arm_assist, "
    "yaw, in that order); GaitManagerError when a command is not finite.")
    .def(
      "__init__",
      [](GaitManagerController * self, nb::handle params) {
        new (self) GaitManagerController(parameters_of(params));
      },
      "params"_a, "From a GaitManagerParameters; ValueError for a bad field.")
    .def(
      "set_parameters",
      [](GaitManagerController & self, nb::handle params) {
        self.set_parameters(parameters_of(params));
      },
      "params"_a, "New parameters from the next observation on (the pace point's start stays).")
    .def_prop_ro(
      "parameters",
      [](const GaitManagerController & self) { return gait_manager::as_dict(self.parameters()); },
      "The parameters the sources run with, as C++ holds them: {block: {field: value}, "
      "'enabled': [sources]}.")
    .def_prop_ro(
      "head_start_y", &GaitManagerController::head_start_y,
      "The head top's y [m] at t = 0 (or at the first observation), the start of the walking "
      "stabiliser's pace point; None before.");
}
