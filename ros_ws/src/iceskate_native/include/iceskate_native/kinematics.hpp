// What the control laws need from the robot model, as an interface: the head pose and its
// Jacobian (visual lifting, docs/model.md §10), gravity terms, the swing heel's height row, the
// centre of mass, frame and joint positions, joint velocities, the constant geometry of a
// support model and the total mass (gait manager, §11). Eigen only, no Pinocchio: a controller
// package compiles against this header alone; ModelKinematics (model_kinematics.hpp) implements
// it on the four support models. Units: SI (m, rad, s, kg, N, N m).
#pragma once

#include <array>

#include <Eigen/Core>

#include "iceskate_native/coordinates.hpp"
#include "iceskate_native/modes.hpp"

namespace iceskate_native
{

/// Which support model a state lives on and which coordinates are locked there: Table-2 mode
/// number (1-20), side 0 right / 1 left, pivot 0 toe / 1 heel.
struct SupportState
{
  int mode = 1;
  int side = 0;
  int pivot = 0;
};

/// The frames the laws use.
enum class Frame
{
  kHeadTop,
  kSwingHeel,
  kSupportToe,
  kSupportHeel,
  kPelvisCentre
};

/// The name of each Frame, in Frame's order (as in iceskate_sim.model.robot.SupportModel).
constexpr std::array<const char *, 5> kFrameNames = {
  "head_top", "swing_heel", "support_toe", "support_heel", "pelvis_centre"};

/// Head-top pose psi = (y [m], z [m], pitch [rad]) and J_H = d psi / d q (3 x 18; columns of
/// locked coordinates 0). Pitch is the angle of the head z axis in the world y-z plane
/// (positive tilts the head back).
struct HeadPose
{
  Eigen::Vector3d psi = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, kCoordinates> jacobian =
    Eigen::Matrix<double, 3, kCoordinates>::Zero();
};

/// The whole-body centre of mass: world position [m], velocity [m/s] and the y row of its
/// Jacobian d y_com / d q (every column).
struct CentreOfMass
{
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Vector18 jacobian_y = Vector18::Zero();
};

/// The robot model as the control laws see it. Joints are numbered by their coordinate
/// (0: y0, i: q_i). State-dependent queries keep a workspace, so an instance is not
/// thread-safe (one per thread), hence non-const.
class Kinematics
{
public:
  virtual ~Kinematics() = default;

  /// Table 2's mode `number` (1-20); std::invalid_argument otherwise.
  virtual const Mode & mode(int number) const = 0;

  /// Total mass of the robot [kg].
  virtual double total_mass() const = 0;

  /// Placement of joint `joint` in its parent joint's frame (constant; the frames are
  /// world-aligned at q = 0) [m].
  virtual Eigen::Vector3d joint_placement(int side, int pivot, int joint) const = 0;

  /// Position of `frame` in its parent joint's frame (constant) [m].
  virtual Eigen::Vector3d frame_offset(int side, int pivot, Frame frame) const = 0;

  /// psi and J_H at q (iceskate_sim.model.dynamics.ModelTerms.head_pose).
  virtual HeadPose head_pose(const SupportState & state, const Vector18 & q) = 0;

  /// g(q), the generalized gravity [N m, N]; entries of locked coordinates 0.
  virtual Vector18 gravity(const SupportState & state, const Vector18 & q) = 0;

  /// d z_heel / d q of the swing heel [m/rad, m/m]; columns of locked coordinates 0.
  virtual Vector18 swing_heel_z_row(const SupportState & state, const Vector18 & q) = 0;

  /// The centre of mass at (q, v).
  virtual CentreOfMass centre_of_mass(const SupportState & state, const Vector18 & q,
                                      const Vector18 & v) = 0;

  /// World position of `frame` at q [m].
  virtual Eigen::Vector3d frame_position(const SupportState & state, const Vector18 & q,
                                         Frame frame) = 0;

  /// World position of joint `joint` at q [m].
  virtual Eigen::Vector3d joint_position(const SupportState & state, const Vector18 & q,
                                         int joint) = 0;

  /// World-aligned linear velocity of joint `joint`'s origin at (q, v) [m/s].
  virtual Eigen::Vector3d joint_velocity(const SupportState & state, const Vector18 & q,
                                         const Vector18 & v, int joint) = 0;
};

}  // namespace iceskate_native
