// The module visual_lifting._law: VisualLiftingController, the C++ law as an
// iceskate_native.Controller (the base type comes from iceskate_native, imported first), built
// from a VisualLiftingParameters object (the one schema): read_visual_lifting, generated from
// visual_lifting/parameters.py, reads every field by its name; a bad field is a ValueError
// naming it.
#include <optional>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/optional.h>

#include "iceskate_native/binding_parameters.hpp"
#include "iceskate_native/controller.hpp"
#include "visual_lifting/law.hpp"
#include "visual_lifting/parameter_readers.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace
{

visual_lifting::VisualLiftingParameters parameters_of(nb::handle object)
{
  return visual_lifting::read_visual_lifting(iceskate_native::binding::Fields(object));
}

}  // namespace

NB_MODULE(_law, m)
{
  m.doc() = "The visual-lifting law (eq. (9)) in C++ as an iceskate_native.Controller.";
  nb::module_::import_("iceskate_native");  // registers the base type Controller

  using visual_lifting::VisualLiftingController;
  nb::class_<VisualLiftingController, iceskate_native::Controller>(
    m, "VisualLiftingController",
    "tau_h = J_H^T K_p (psi_d - psi) as one source 'visual_lifting', with the head target "
    "psi_d; psi(0) is latched at t = 0 (or the first observation).")
    .def(
      "__init__",
      [](VisualLiftingController * self, nb::handle params) {
        new (self) VisualLiftingController(parameters_of(params));
      },
      "params"_a, "From a VisualLiftingParameters; ValueError for a bad field.")
    .def(
      "set_parameters",
      [](VisualLiftingController & self, nb::handle params) {
        self.set_parameters(parameters_of(params));
      },
      "params"_a, "New parameters from the next observation on (psi(0) stays).")
    .def(
      "latch_origin", &VisualLiftingController::latch_origin, "obs"_a, "kinematics"_a,
      "Take the head pose at obs as psi(0), the target's origin.")
    .def_prop_ro(
      "parameters",
      [](const VisualLiftingController & self) {
        return visual_lifting::as_dict(self.parameters());
      },
      "The parameters the law runs with, as C++ holds them: {field: value}.")
    .def_prop_ro(
      "origin",
      [](const VisualLiftingController & self) -> std::optional<Eigen::Vector3d> {
        return self.origin();
      },
      "psi(0) (y [m], z [m], pitch [rad]), None before it is latched.");
}
