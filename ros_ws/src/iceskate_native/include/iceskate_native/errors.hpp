// Error types of the native kernels and how they reach Python.
//
//   std::invalid_argument (or std::domain_error / std::length_error)  -> ValueError
//       bad input from the caller: wrong length, NaN, malformed model bytes. nanobind translates
//       these standard exceptions itself.
//   iceskate_native::NativeError                                       -> iceskate_native.NativeError
//       a failure inside a kernel on valid input (a singular matrix, a diverging solve, ...).
//       Registered in bindings.cpp as a subclass of RuntimeError; iceskate_sim (a layer above)
//       catches it and raises its own SimulationError with the time, mode and state.
//   iceskate_native::ControllerError                               -> iceskate_native.ControllerError
//       a controller written in Python (a subclass of iceskate_native.Controller) that raised
//       or answered a command of the wrong size or not finite; its message names the
//       controller. A kind of NativeError.
//
// Never let any other exception type or a crash cross the boundary: an unknown C++ exception
// reaches Python as a bare RuntimeError without context.
#pragma once

#include <stdexcept>
#include <string>

namespace iceskate_native
{

class NativeError : public std::runtime_error
{
public:
  using std::runtime_error::runtime_error;
};

class ControllerError : public NativeError
{
public:
  using NativeError::NativeError;
};

}  // namespace iceskate_native
