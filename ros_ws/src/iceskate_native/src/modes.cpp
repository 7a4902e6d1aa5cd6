#include "iceskate_native/modes.hpp"

#include <sstream>
#include <stdexcept>
#include <string>

namespace iceskate_native
{

int Mode::multiplier_index(Constraint c) const
{
  for (std::size_t k = 0; k < constraints.size(); ++k) {
    if (constraints[k] == c) {
      return static_cast<int>(k);
    }
  }
  return -1;
}

void check_modes(const ModeTable & modes)
{
  if (modes.empty()) {
    throw std::invalid_argument("the mode table is empty");
  }
  for (std::size_t k = 0; k < modes.size(); ++k) {
    const Mode & mode = modes[k];
    std::ostringstream problem;
    if (mode.number != static_cast<int>(k) + 1) {
      problem << "mode table entry " << k << " has number " << mode.number;
    } else if (mode.active.empty() || mode.active.size() > kCoordinates) {
      problem << "mode " << mode.number << " has " << mode.active.size() << " coordinates";
    } else if (mode.constraints.size() > 3) {
      problem << "mode " << mode.number << " has " << mode.constraints.size() << " constraints";
    } else if (!mode.constraints.empty() && mode.constraints.front() != Constraint::kHeelZ) {
      problem << "mode " << mode.number << ": the heel-height constraint must come first";
    } else if (mode.y0_active != (mode.active.front() == kY0)) {
      problem << "mode " << mode.number << ": y0 active and the coordinate list disagree";
    } else if (
      mode.q1_active != (mode.active.size() > (mode.y0_active ? 1U : 0U)
                         && mode.active[mode.y0_active ? 1 : 0] == kQ1)) {
      problem << "mode " << mode.number << ": q1 active and the coordinate list disagree";
    }
    for (std::size_t i = 0; problem.str().empty() && i < mode.active.size(); ++i) {
      const int index = mode.active[i];
      if (index < 0 || index >= kCoordinates || (i > 0 && index <= mode.active[i - 1])) {
        problem << "mode " << mode.number << ": active coordinates must be increasing in 0..17";
      }
    }
    if (!problem.str().empty()) {
      throw std::invalid_argument(problem.str());
    }
  }
}

const Mode & mode_numbered(const ModeTable & modes, int number)
{
  if (number < 1 || static_cast<std::size_t>(number) > modes.size()) {
    throw std::invalid_argument("unknown gait mode " + std::to_string(number)
                                + "; the mode table has modes 1-" + std::to_string(modes.size()));
  }
  return modes[static_cast<std::size_t>(number - 1)];
}

}  // namespace iceskate_native
