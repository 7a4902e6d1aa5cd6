// The controllers' view of a hybrid state, built in this one place for the loop's controllers,
// the first observation of a run and Python (HybridSimulator.observation): what a GaitState
// message carries, so a controller answers the same in-process as from the message.
#pragma once

#include <cstdint>

#include "iceskate_native/controller.hpp"
#include "iceskate_native/modes.hpp"
#include "iceskate_native/transitions.hpp"

namespace iceskate_native
{

/// t [s] >= 0 as a ROS stamp's whole nanoseconds (ties to even), as a message carries it.
std::int64_t stamp_ns(double t);

/// t [s] at a stamp's resolution.
double stamp_time(double t);

/// The observation of `s` in its mode `mode`: times at a stamp's resolution, and the pivot
/// 'toe' while the sole is flat (q1 locked: GaitState has no pivot then, and the support
/// models of either edge give the same kinematics to rounding).
Observation observation_of(const HybridState & s, const Mode & mode);

}  // namespace iceskate_native
