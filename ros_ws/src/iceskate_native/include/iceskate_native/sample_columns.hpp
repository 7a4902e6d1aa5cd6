// The recorded sample, declared once: one row per quantity, expanded into the SampleBlock's
// columns and for_each_column (control_loop.hpp), the Python table iceskate_native.SAMPLE_COLUMNS
// and, through that, the messages' writer, the bag reader and the trajectory's columns
// (docs/architecture.md, 'One sample form').
//
// X(name, element type, values per sample, unit, saved, routes, meaning):
//   - values per sample: kPerTfPair for the /tf column (kTfPoseWidth per (parent, child) pair);
//   - saved: whether trajectory.npz keeps the column;
//   - routes: where the values go in the recorded messages, "topic:field" separated by spaces,
//     the field holding the column's values in order (a Point's or Quaternion's fields as
//     "pose.position.x,y,z"); the first route is the one the bag reader reads back. Columns a
//     message holds in another form (the multipliers by name, the stamps, the sources' efforts,
//     /tf) are written by iceskate_sim.recording.messages and have no route.
#pragma once

#include <cstddef>
#include <cstdint>

#include "iceskate_native/coordinates.hpp"

namespace iceskate_native
{

/// The values per sample of a column that holds kTfPoseWidth per /tf pair.
constexpr std::size_t kPerTfPair = 0;
/// x, y, z [m], qx, qy, qz, qw: a /tf child link's placement in its parent's (or the world's).
constexpr std::size_t kTfPoseWidth = 7;

/// The values per sample of a column declared `width` values per sample, with `tf_pairs` pairs.
constexpr std::size_t sample_width(std::size_t width, std::size_t tf_pairs)
{
  return width == kPerTfPair ? kTfPoseWidth * tf_pairs : width;
}

// clang-format off
#define ICESKATE_SAMPLE_COLUMNS(X)                                                               \
  X(t, double, 1, "s", true, "",                                                                 \
    "time t_k of the sample")                                                                    \
  X(t_exchange, double, 1, "s", false, "",                                                       \
    "time t_e of the latest support exchange (0 before the first)")                              \
  X(t_touchdown, double, 1, "s", false, "",                                                      \
    "time of the swing heel's strike in this step (NaN: not yet)")                               \
  X(heel_anchor_y, double, 1, "m", false, "/gait_state:heel_anchor_y",                           \
    "world y at which a pinned swing heel is held (0: not pinned)")                              \
  X(mode, std::int32_t, 1, "", true, "/gait_state:mode",                                         \
    "the gait state (mode) of Table 2, 1-20")                                                    \
  X(side, std::int32_t, 1, "", true, "/gait_state:support_side",                                 \
    "the support foot: 0 right, 1 left")                                                         \
  X(pivot, std::int32_t, 1, "", true, "/gait_state:pivot",                                       \
    "the sole edge q1 rotates about: 0 none (flat sole, q1 locked), 1 toe, 2 heel")              \
  X(step_index, std::int32_t, 1, "", true, "/gait_state:step_index",                             \
    "support exchanges since the start")                                                         \
  X(q, double, kCoordinates, "m, rad", true, "/joint_states:position /gait_state:position",      \
    "positions of y0, q1..q17")                                                                  \
  X(v, double, kCoordinates, "m/s, rad/s", true, "/joint_states:velocity /gait_state:velocity",  \
    "velocities of y0, q1..q17")                                                                 \
  X(qdd, double, kCoordinates, "m/s^2, rad/s^2", true, "/joint_dynamics:acceleration",           \
    "accelerations under the commands held over the period (0 where inactive)")                  \
  X(passive, double, kCoordinates, "N, N m", false, "",                                          \
    "joint damping and soft stops (/joint_dynamics' source 'passive')")                          \
  X(applied, double, kCoordinates, "N, N m", true, "",                                           \
    "every generalized force applied: inputs, damping and stops")                                \
  X(multipliers, double, 3, "N, N, N m", true, "",                                               \
    "Lagrange multipliers f_nz, f_ny, tau_n of the swing constraints (0 where inactive)")        \
  X(support_normal, double, 1, "N", true, "/gait_state:support_normal_force",                    \
    "normal force N_s on the support foot")                                                      \
  X(support_friction, double, 1, "N", true, "/gait_state:support_friction_force",                \
    "friction force F_y on the support foot, along world y")                                     \
  X(zmp_y, double, 1, "m", true, "/gait_state:zmp.y",                                            \
    "world y of the ZMP, the support foot's centre of pressure (NaN: no support force)")         \
  X(zmp_inside_support, std::uint8_t, 1, "", false, "/gait_state:zmp_inside_support",            \
    "the ZMP lies on the flat support sole")                                                     \
  X(swing_clearance, double, 1, "m", true, "/gait_state:swing_clearance",                        \
    "height of the swing sole's lower end (heel or toe) above the ice")                          \
  X(y0_active, std::uint8_t, 1, "", false, "/gait_state:y0_active",                              \
    "y0 (the glide) is a coordinate of the mode")                                                \
  X(q1_active, std::uint8_t, 1, "", false, "/gait_state:q1_active",                              \
    "q1 (the tip about a sole edge) is a coordinate of the mode")                                \
  X(touched_down, std::uint8_t, 1, "", false, "/gait_state:touched_down",                        \
    "the swing heel has struck in this step")                                                    \
  X(active, std::uint8_t, kCoordinates, "", false, "/joint_dynamics:active",                     \
    "the mode's active coordinates")                                                             \
  X(effort_total, double, kCoordinates, "N, N m", false, "/joint_states:effort",                 \
    "the sum of the sources' efforts")                                                           \
  X(head_position, double, 3, "m", false, "/head_pose:pose.position.x,y,z",                      \
    "the head top's world position observed at t_k")                                             \
  X(head_orientation, double, 4, "", false, "/head_pose:pose.orientation.x,y,z,w",               \
    "the head top's world orientation, quaternion x, y, z, w")                                   \
  X(head_pitch, double, 1, "rad", false, "",                                                     \
    "the head top's pitch atan2(-R(1,2), R(2,2)) of its rotation R")                             \
  X(head_target, double, 3, "m, m, rad", true, "",                                               \
    "the head target psi_d steered to: y, z, pitch")                                             \
  X(tf, double, kPerTfPair, "m, -", false, "",                                                   \
    "per /tf pair, the child link's placement in its parent's: x, y, z, qx, qy, qz, qw")         \
  X(last_event, std::int64_t, 1, "", false, "",                                                  \
    "index in the event log of the latest transition at or before t_k (-1: none)")               \
  X(stamps_ns, std::int64_t, 4, "ns", false, "",                                                 \
    "t, t_exchange, t_touchdown (0 before it), the latest transition's t (0: none), whole ns")   \
  X(present, std::uint64_t, 1, "", false, "",                                                    \
    "bit i: source i answered at t_k")
// clang-format on

}  // namespace iceskate_native
