// The visual-lifting law, the paper's eqs. (8)-(9) (docs/model.md §10), in C++: the head-top pose
// psi = (y_H [m], z_H [m], pitch [rad]) is pulled towards a target psi_d by a virtual spring,
// tau_h = J_H(q)^T K_p (psi_d - psi) on the listed joints active in the mode. The target starts
// at psi(0) (latched at t = 0), moves as desired_y says and follows the moving stance. Its
// parameters: VisualLiftingParameters (visual_lifting/parameters.hpp, generated from
// visual_lifting/parameters.py).
#pragma once

#include <optional>

#include <Eigen/Core>

#include "iceskate_native/controller.hpp"
#include "iceskate_native/stance.hpp"
#include "visual_lifting/parameters.hpp"

namespace visual_lifting
{

/// psi_d at time t [s] from the current pose psi, the origin psi(0) and the stance offset
/// (dy, dz) [m] ('follow' ignores dy).
Eigen::Vector3d desired_head_pose(
  const VisualLiftingParameters & params, double t, const Eigen::Vector3d & psi,
  const Eigen::Vector3d & origin, const Eigen::Vector2d & offset);

/// psi_d - psi with |delta y| saturated at max_dy.
Eigen::Vector3d head_error(
  const VisualLiftingParameters & params, const Eigen::Vector3d & psi_d,
  const Eigen::Vector3d & psi);

/// Eq. (9) as a controller: one source 'visual_lifting' (a torque) and the head target.
class VisualLiftingController final : public iceskate_native::Controller
{
public:
  explicit VisualLiftingController(VisualLiftingParameters params);

  void compute(
    const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
    iceskate_native::ControllerOutput & out) override;

  /// Latch psi(0), the target's origin, at the head pose of `obs` (compute does it at t = 0,
  /// and at the first observation when none is latched).
  void latch_origin(
    const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics);

  /// New parameters from the next call on (the origin stays).
  void set_parameters(VisualLiftingParameters params);

  const VisualLiftingParameters & parameters() const noexcept { return params_; }
  const std::optional<Eigen::Vector3d> & origin() const noexcept { return origin_; }

private:
  VisualLiftingParameters params_;
  std::optional<Eigen::Vector3d> origin_;
};

}  // namespace visual_lifting
