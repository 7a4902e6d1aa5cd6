// Reading a law's Python parameter object (a frozen dataclass of iceskate_native.parameters, the one
// schema) into C++ in a controller package's nanobind module. The dataclass has checked its
// rules already; this checks again what C++ relies on: numbers finite, lists of the right length
// and range, choices known. A bad field is std::invalid_argument (ValueError in Python) in one
// sentence naming it. Binding code only (needs nanobind): the laws never include it.
#pragma once

#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>

namespace iceskate_native::binding
{

/// The fields of one parameter block; `prefix` names it in messages (e.g. "posture.").
class Fields
{
public:
  explicit Fields(nanobind::handle block, std::string prefix = "")
  : block_(nanobind::borrow(block)), prefix_(std::move(prefix))
  {
  }

  /// The nested block `name`.
  Fields block(const char * name) const { return Fields(get(name), path(name) + "."); }

  /// A finite number.
  double number(const char * name) const
  {
    const double value = cast<double>(get(name), name, "a number");
    if (!std::isfinite(value)) {
      throw std::invalid_argument(
        path(name) + " is " + std::to_string(value) + ": every parameter must be finite");
    }
    return value;
  }

  /// A finite number, or unset (None).
  std::optional<double> optional_number(const char * name) const
  {
    return get(name).is_none() ? std::nullopt : std::optional<double>(number(name));
  }

  std::string text(const char * name) const { return cast<std::string>(get(name), name, "text"); }

  bool flag(const char * name) const
  {
    const nanobind::object value = get(name);
    if (!nanobind::isinstance<nanobind::bool_>(value)) {
      throw std::invalid_argument(path(name) + " must be true or false");
    }
    return nanobind::cast<bool>(value);
  }

  /// An integer >= low.
  int integer(const char * name, int low) const
  {
    const int value = cast<int>(get(name), name, "an integer");
    if (value < low) {
      throw std::invalid_argument(
        path(name) + " is " + std::to_string(value) + ", expected >= " + std::to_string(low));
    }
    return value;
  }

  /// Exactly `size` finite numbers.
  std::vector<double> numbers(const char * name, std::size_t size) const
  {
    std::vector<double> out;
    for (nanobind::handle item : get(name)) {
      out.push_back(cast<double>(item, name, "a list of numbers"));
    }
    if (out.size() != size) {
      throw std::invalid_argument(path(name) + " has " + std::to_string(out.size())
                                  + " entries, expected " + std::to_string(size));
    }
    for (double value : out) {
      if (!std::isfinite(value)) {
        throw std::invalid_argument(path(name) + " has a non-finite entry: every parameter "
                                    "must be finite");
      }
    }
    return out;
  }

  /// Joint numbers (coordinates) in [low, high].
  std::vector<int> joints(const char * name, int low, int high) const
  {
    std::vector<int> out;
    for (nanobind::handle item : get(name)) {
      const int joint = cast<int>(item, name, "a list of joint numbers");
      if (joint < low || joint > high) {
        throw std::invalid_argument(path(name) + " holds joint " + std::to_string(joint)
                                    + ", expected joints " + std::to_string(low) + "-"
                                    + std::to_string(high));
      }
      out.push_back(joint);
    }
    return out;
  }

  /// The option named by text field `name`: Option(k) for names[k].
  template <class Option, std::size_t N>
  Option choice(const char * name, const std::array<const char *, N> & names) const
  {
    return static_cast<Option>(index(cast<std::string>(get(name), name, "text"), name, names));
  }

  /// Which of `names` the collection `name` (a set or list of text) holds.
  template <std::size_t N>
  std::array<bool, N> set(const char * name, const std::array<const char *, N> & names) const
  {
    std::array<bool, N> out{};
    for (nanobind::handle item : get(name)) {
      out[index(cast<std::string>(item, name, "a list of text"), name, names)] = true;
    }
    return out;
  }

private:
  std::string path(const char * name) const { return prefix_ + name; }

  nanobind::object get(const char * name) const
  {
    if (!nanobind::hasattr(block_, name)) {
      throw std::invalid_argument("the parameters have no field " + path(name));
    }
    return block_.attr(name);
  }

  /// k for text == names[k]; std::invalid_argument naming field `name` otherwise.
  template <std::size_t N>
  std::size_t index(
    const std::string & text, const char * name, const std::array<const char *, N> & names) const
  {
    std::string known;
    for (std::size_t k = 0; k < N; ++k) {
      if (text == names[k]) {
        return k;
      }
      known += (k == 0 ? "" : ", ") + std::string(names[k]);
    }
    throw std::invalid_argument(path(name) + " '" + text + "' is not one of " + known);
  }

  template <class T>
  T cast(nanobind::handle value, const char * name, const char * kind) const
  {
    T out{};
    if (!nanobind::try_cast(value, out)) {
      throw std::invalid_argument(path(name) + " must be " + kind);
    }
    return out;
  }

  nanobind::object block_;
  std::string prefix_;
};

}  // namespace iceskate_native::binding
