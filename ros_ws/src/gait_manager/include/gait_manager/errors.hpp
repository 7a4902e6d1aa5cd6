// The one error of the gait-manager laws: a command that is not finite (the module _law turns it
// into gait_manager.errors.GaitManagerError).
#pragma once

#include <stdexcept>

namespace gait_manager
{

class GaitManagerError : public std::runtime_error
{
public:
  using std::runtime_error::runtime_error;
};

}  // namespace gait_manager
