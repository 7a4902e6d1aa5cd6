// Constants the gait-manager laws share.
#pragma once

namespace gait_manager
{

constexpr double kPi = 3.141592653589793;  // the double nearest pi (Python's math.pi)
constexpr double kGravity = 9.81;          // [m/s^2], as the model's

}  // namespace gait_manager
