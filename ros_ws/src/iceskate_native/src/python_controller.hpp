// A controller written in Python (docs/usage.md, "Your own controller", for its answer): a
// Python subclass of iceskate_native.Controller whose method compute(obs, kinematics) returns its
// command. PythonLaw is the C++ Controller that calls that method under the GIL (ControlLoop.run
// releases it) and checks and converts its answer; a wrong answer or an exception in compute is a
// ControllerError naming the controller and the time. PythonController is PythonLaw's nanobind
// trampoline, the type bound as iceskate_native.Controller. Private to iceskate_native._kernel.
#pragma once

#include <string>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/trampoline.h>

#include "iceskate_native/controller.hpp"
#include "iceskate_native/kinematics.hpp"

namespace iceskate_native::bindings
{

class PythonLaw : public Controller
{
public:
  /// Acquires the GIL, calls law() and fills `out` with its checked answer.
  void compute(const Observation & obs, Kinematics & kinematics, ControllerOutput & out) final;

  /// What the Python method compute(obs, kinematics) returns (GIL held).
  virtual nanobind::object law(const Observation & obs, Kinematics * kinematics) = 0;
  /// The Python object this controller is.
  virtual nanobind::handle self() const = 0;

private:
  /// The source names (the attribute `sources`, else the controller's name), read once.
  const std::vector<std::string> & sources(const Observation & obs);

  std::vector<std::string> sources_;
};

class PythonController final : public PythonLaw
{
public:
  NB_TRAMPOLINE(PythonLaw);

  nanobind::object law(const Observation & obs, Kinematics * kinematics) override
  {
    NB_OVERRIDE_PURE_NAME("compute", law, obs, kinematics);
  }

  nanobind::handle self() const override { return nb_trampoline.base(); }
};

}  // namespace iceskate_native::bindings
