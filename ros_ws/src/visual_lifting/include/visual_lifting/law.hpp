// The visual-lifting law, the paper's eqs. (8)-(9) (docs/model.md §10), in C++: the head-top pose
// psi = (y_H [m], z_H [m], pitch [rad]) is pulled towards a target psi_d by a virtual spring,
// tau_h = J_H(q)^T K_p (psi_d - psi) on the listed joints active in the mode. The target starts
// at psi(0) (latched at t = 0), moves as desired_y says and follows the moving stance. The
// counterpart of visual_lifting/law.py (the readable reference it is tested against).
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "iceskate_native/controller.hpp"
#include "iceskate_native/stance.hpp"

namespace visual_lifting
{

/// The forward target y_d: 'moving' y_H(0) + v_d t, 'follow' y_H(t) (no forward error), 'fixed'
/// y_H(0).
enum class DesiredY
{
  kMoving,
  kFollow,
  kFixed
};

/// VisualLiftingParameters (visual_lifting/law.py, the one schema: values come from there).
struct Parameters
{
  Eigen::Vector3d kp = Eigen::Vector3d::Zero();  ///< K_p on (y, z, pitch) [N/m, N/m, N m/rad]
  std::vector<int> joints;                       ///< joints that receive the torque (1-17)
  bool joint1_torque = false;                    ///< the q1 entry while q1 is active
  DesiredY desired_y = DesiredY::kMoving;
  double v_d = 0.0;                  ///< forward speed of the 'moving' target [m/s]
  std::optional<double> z_d;         ///< target head height [m]; unset: the initial height
  double pitch_d = 0.0;              ///< target head pitch [rad]
  std::optional<double> max_dy;      ///< saturation of |y_d - y| [m]; unset: none
  iceskate_native::StanceSchedule stance;  ///< the target's shift (shift_* fields)
};

/// psi_d at time t [s] from the current pose psi, the origin psi(0) and the stance offset
/// (dy, dz) [m] ('follow' ignores dy).
Eigen::Vector3d desired_head_pose(
  const Parameters & params, double t, const Eigen::Vector3d & psi,
  const Eigen::Vector3d & origin, const Eigen::Vector2d & offset);

/// psi_d - psi with |delta y| saturated at max_dy.
Eigen::Vector3d head_error(
  const Parameters & params, const Eigen::Vector3d & psi_d, const Eigen::Vector3d & psi);

/// Eq. (9) as a controller: one source 'visual_lifting' (a torque) and the head target.
class VisualLiftingController final : public iceskate_native::Controller
{
public:
  explicit VisualLiftingController(Parameters params);

  void compute(
    const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
    iceskate_native::ControllerOutput & out) override;

  /// Latch psi(0), the target's origin, at the head pose of `obs` (compute does it at t = 0,
  /// and at the first observation when none is latched).
  void latch_origin(
    const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics);

  /// New parameters from the next call on (the origin stays).
  void set_parameters(Parameters params);

  const Parameters & parameters() const noexcept { return params_; }
  const std::optional<Eigen::Vector3d> & origin() const noexcept { return origin_; }

private:
  Parameters params_;
  std::optional<Eigen::Vector3d> origin_;
};

}  // namespace visual_lifting
