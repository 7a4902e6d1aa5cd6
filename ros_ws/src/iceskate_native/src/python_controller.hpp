// A controller written in Python (docs/usage.md, "Your own controller"): a Python subclass of
// iceskate_native.Controller whose method compute(obs, kinematics) returns its command. PythonLaw
// is the C++ Controller that calls that method, under the GIL (ControlLoop.run releases it), and
// checks and converts its answer; PythonController is PythonLaw's nanobind trampoline, the type
// bound as iceskate_native.Controller. Private to the module iceskate_native._kernel.
//
// The answer, in SI units ([y0, q1..q17]: N, N m; N m/rad, N m s/rad; m, rad):
//   tau                                  (18,) the generalized force of the controller's one source
//   {'effort': tau, 'stiffness': k, 'damping': d, 'reference': q_ref, 'head_target': psi_d}
//                                        one source with an impedance (k, d, q_ref: all or none)
//   {'sources': {name: tau or {'effort': ..., ...}, ...}, 'head_target': psi_d}
//                                        every source of `sources`, each a torque or a command
// A wrong size, a value that is not finite, a negative gain, an unknown key or source, and an
// exception raised by compute are a ControllerError naming the controller and the time.
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
