// PythonLaw (python_controller.hpp): a Python controller's answer checked and converted into a
// ControllerOutput, and its failures as one ControllerError naming it.
#include "python_controller.hpp"

#include <algorithm>
#include <cstdio>
#include <functional>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "bindings.hpp"
#include "iceskate_native/checks.hpp"
#include "iceskate_native/errors.hpp"

namespace nb = nanobind;

namespace iceskate_native::bindings
{

namespace
{

nb::handle controller_error_type;  // iceskate_native.ControllerError (kept by the module)

constexpr const char * kJoints = "[y0, q1..q17]";

/// str(value) as text (nb::str of an attribute accessor would take it for a str as it is).
std::string text(nb::handle value) { return nb::str(value).c_str(); }

/// "controller 'name' (module.Class) at t=0.123 s": who failed, for the messages.
std::string who(nb::handle self, double t)
{
  const nb::handle type = self.type();
  const std::string kind = text(type.attr("__module__")) + "." + text(type.attr("__qualname__"));
  const nb::object name = nb::getattr(self, "name", nb::none());
  char when[48];
  std::snprintf(when, sizeof when, " at t=%.6f s", t);
  return "controller "
         + (nb::isinstance<nb::str>(name) ? "'" + text(name) + "' (" + kind + ")" : kind) + when;
}

/// Who failed, built only when something did (it asks Python for names).
using Where = std::function<std::string()>;

/// A 1-D array of `size` finite numbers (any sequence numpy.asarray takes).
Eigen::VectorXd numbers(
  nb::handle value, Eigen::Index size, const std::string & what, const char * meaning,
  const Where & where)
{
  Eigen::VectorXd out;
  if (!nb::try_cast<Eigen::VectorXd>(value, out)) {
    nb::object array;
    try {
      array = nb::module_::import_("numpy").attr("asarray")(value, "float64");
    } catch (const nb::python_error &) {
      throw ControllerError(where() + ": " + what + " is a " +
                            nb::type_name(value.type()).c_str() + ", not an array of numbers");
    }
    if (!nb::try_cast<Eigen::VectorXd>(array, out)) {
      throw ControllerError(where() + ": " + what + " has the shape " +
                            text(array.attr("shape")) + ", expected (" +
                            std::to_string(size) + ",)");
    }
  }
  try {
    require_finite_vector(out, size, what.c_str(), meaning);
  } catch (const std::invalid_argument & error) {
    throw ControllerError(where() + ": " + error.what());
  }
  return out;
}

/// `mapping`'s keys must be among `allowed` (a ControllerError naming the first other one).
void require_keys(
  const nb::dict & mapping, std::initializer_list<const char *> allowed, const std::string & what,
  const Where & where)
{
  for (const auto & [key, value] : mapping) {
    const auto named_key = [&key](const char * name) {
      return nb::isinstance<nb::str>(key) && nb::str(key).equal(nb::str(name));
    };
    if (std::none_of(allowed.begin(), allowed.end(), named_key)) {
      std::string names;
      for (const char * name : allowed) {
        names += std::string(names.empty() ? "" : ", ") + name;
      }
      throw ControllerError(where() + ": unknown key " + nb::repr(key).c_str() + " in " + what +
                            " (" + names + ")");
    }
  }
}

/// One source's command: a torque, or a mapping with an effort and maybe an impedance.
void read_command(
  nb::handle value, const std::string & source, JointCommand & command, bool top,
  const Where & where)
{
  const auto joints = [&](nb::handle array, const char * key) {  // one of its (18,) arrays
    return numbers(array, kCoordinates, "source '" + source + "' " + key, kJoints, where);
  };
  if (!nb::isinstance<nb::dict>(value)) {
    command.set_torque(joints(value, "torque"));
    return;
  }
  const nb::dict mapping = nb::borrow<nb::dict>(value);
  if (top) {
    require_keys(mapping, {"effort", "stiffness", "damping", "reference", "head_target"},
                 "the answer", where);
  } else {
    require_keys(mapping, {"effort", "stiffness", "damping", "reference"},
                 "the command of source '" + source + "'", where);
  }
  if (!mapping.contains("effort")) {
    throw ControllerError(where() + ": the command of source '" + source + "' has no 'effort'");
  }
  command.effort = joints(mapping["effort"], "effort");
  const int gains = static_cast<int>(mapping.contains("stiffness")) +
                    static_cast<int>(mapping.contains("damping")) +
                    static_cast<int>(mapping.contains("reference"));
  command.has_impedance = gains > 0;
  if (gains == 0) {
    return;
  }
  if (gains != 3) {
    throw ControllerError(where() + ": the command of source '" + source + "' needs all of "
                          "'stiffness', 'damping' and 'reference' or none");
  }
  command.stiffness = joints(mapping["stiffness"], "stiffness");
  command.damping = joints(mapping["damping"], "damping");
  command.reference = joints(mapping["reference"], "reference");
  if (command.stiffness.minCoeff() < 0.0 || command.damping.minCoeff() < 0.0) {
    throw ControllerError(where() + ": the stiffness and damping of source '" + source +
                          "' must be >= 0");
  }
}

/// The answer of a Python controller with sources `sources` into `out`.
void read_answer(
  nb::handle answer, const std::vector<std::string> & sources, ControllerOutput & out,
  const Where & where)
{
  out.clear();
  if (!nb::isinstance<nb::dict>(answer) || !nb::borrow<nb::dict>(answer).contains("sources")) {
    if (sources.size() != 1) {
      throw ControllerError(where() + ": it has " + std::to_string(sources.size()) +
                            " sources, so its answer needs their commands under 'sources'");
    }
    read_command(answer, sources[0], out.add(sources[0].c_str()), true, where);
  } else {
    const nb::dict mapping = nb::borrow<nb::dict>(answer);
    require_keys(mapping, {"sources", "head_target"}, "an answer with 'sources'", where);
    const nb::handle commands = mapping["sources"];
    if (!nb::isinstance<nb::dict>(commands)) {
      throw ControllerError(where() + ": its 'sources' is a " +
                            nb::type_name(commands.type()).c_str() + ", not a dict");
    }
    const nb::dict by_source = nb::borrow<nb::dict>(commands);
    if (by_source.size() != sources.size()) {
      throw ControllerError(where() + ": it answered " + std::to_string(by_source.size()) +
                            " sources, expected its " + std::to_string(sources.size()) +
                            " (attribute 'sources')");
    }
    for (const std::string & source : sources) {
      const nb::str key(source.c_str());
      if (!by_source.contains(key)) {
        throw ControllerError(where() + ": its answer has no command of source '" + source + "'");
      }
      read_command(by_source[key], source, out.add(source.c_str()), false, where);
    }
  }
  if (nb::isinstance<nb::dict>(answer) && nb::borrow<nb::dict>(answer).contains("head_target")) {
    out.has_head_target = true;
    out.head_target = numbers(nb::borrow<nb::dict>(answer)["head_target"], 3, "head_target",
                              "y [m], z [m], pitch [rad]", where);
  }
}

/// "file.py:42", where the innermost frame of `traceback` was ('' without one).
std::string innermost(nb::handle traceback)
{
  if (!traceback.is_valid() || traceback.is_none()) {
    return "";
  }
  nb::handle tb = traceback;
  while (!tb.attr("tb_next").is_none()) {
    tb = tb.attr("tb_next");
  }
  const std::string file = text(tb.attr("tb_frame").attr("f_code").attr("co_filename"));
  const auto slash = file.find_last_of('/');
  return (slash == std::string::npos ? file : file.substr(slash + 1)) + ":" +
         text(tb.attr("tb_lineno"));
}

}  // namespace

const std::vector<std::string> & PythonLaw::sources(const Observation & obs)
{
  if (!sources_.empty()) {
    return sources_;
  }
  const nb::handle me = self();
  nb::object names = nb::getattr(me, "sources", nb::none());
  if (names.is_none()) {
    const nb::object name = nb::getattr(me, "name", nb::none());
    names = nb::make_tuple(name.is_none() ? me.type().attr("__name__") : name);
  }
  std::vector<std::string> out;
  if (!nb::try_cast<std::vector<std::string>>(names, out) || out.empty() ||
      nb::isinstance<nb::str>(names)) {
    throw ControllerError(who(me, obs.t) + ": its 'sources' must be a non-empty sequence of "
                          "names, got " + nb::repr(names).c_str());
  }
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (out[i].empty() || std::find(out.begin(), out.begin() + i, out[i]) != out.begin() + i) {
      throw ControllerError(who(me, obs.t) + ": its 'sources' must be distinct non-empty "
                            "names, got " + nb::repr(names).c_str());
    }
  }
  sources_ = std::move(out);
  return sources_;
}

void PythonLaw::compute(const Observation & obs, Kinematics & kinematics, ControllerOutput & out)
{
  nb::gil_scoped_acquire gil;  // ControlLoop.run runs without it
  const std::vector<std::string> & names = sources(obs);
  nb::object answer;
  try {
    answer = law(obs, &kinematics);
  } catch (nb::python_error & error) {
    const std::string where = innermost(error.value().attr("__traceback__"));
    const std::string message = who(self(), obs.t) + ": " + text(nb::type_name(error.type())) +
                                ": " + text(error.value()) +
                                (where.empty() ? "" : " (" + where + ")");
    nb::raise_from(error, controller_error_type, "%s", message.c_str());
  } catch (const std::exception & error) {
    const bool missing = std::string(error.what()).find("pure virtual") != std::string::npos;
    throw ControllerError(who(self(), obs.t) + ": " +
                          (missing ? "its class defines no compute(obs, kinematics)"
                                   : std::string(error.what())));
  }
  read_answer(answer, names, out, [this, &obs] { return who(self(), obs.t); });
}

void bind_controller_error(nb::module_ & m, nb::handle native_error)
{
  controller_error_type =
    nb::exception<ControllerError>(m, "ControllerError", native_error.ptr());
}

}  // namespace iceskate_native::bindings
