// The Python module iceskate_native._kernel: a thin layer of nanobind declarations over the
// C++ API in include/iceskate_native/. No Pinocchio header is included here (only the forward
// declarations behind model.hpp), so this file compiles in seconds; put logic in the core
// library, not here.
//
// Errors: see errors.hpp. std::invalid_argument -> ValueError (nanobind's own translation),
// iceskate_native::NativeError -> iceskate_native.NativeError (a RuntimeError).
#include <string>
#include <string_view>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>

#include "iceskate_native/errors.hpp"
#include "iceskate_native/inertia.hpp"
#include "iceskate_native/model.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace
{

using iceskate_native::RobotModel;
using Vector = Eigen::Ref<const Eigen::VectorXd>;

std::string_view view(const nb::bytes & data) { return {data.c_str(), data.size()}; }

}  // namespace

NB_MODULE(_kernel, m)
{
  m.doc() = "Native (C++) kernels of the iceskate simulator on Pinocchio's C++ API.";

  nb::exception<iceskate_native::NativeError>(m, "NativeError", PyExc_RuntimeError);

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

  m.def(
    "crba_of", &iceskate_native::crba_of, "model"_a, "q"_a,
    "The joint-space inertia matrix M(q) (nv x nv, symmetric) by Pinocchio's CRBA. "
    "ValueError if q does not have model.nq finite entries.");
  m.def(
    "crba_of",
    [](const nb::bytes & model, const Vector & q) {
      return iceskate_native::crba_of(RobotModel::from_bytes(view(model)), q);
    },
    "model"_a, "q"_a,
    "As crba_of(RobotModel, q), from the model's archive bytes (decoded at every call: load a "
    "RobotModel once instead in a loop).");
}
