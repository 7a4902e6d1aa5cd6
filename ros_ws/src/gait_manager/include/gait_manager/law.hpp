// Every gait-manager torque source behind iceskate_native's controller interface (docs/model.md
// §11): the enabled sources only, in the order posture, feedforward, weight_transfer, heel,
// arm_assist, yaw (Source, kSourceNames); the posture source is the walking stabiliser when its
// reference is 'balance'. Its parameters: GaitManagerParameters (gait_manager/parameters.hpp,
// generated from gait_manager/parameters.py).
#pragma once

#include <optional>

#include "gait_manager/arm_assist.hpp"
#include "gait_manager/balance.hpp"
#include "gait_manager/feedforward.hpp"
#include "gait_manager/heel.hpp"
#include "gait_manager/parameters.hpp"
#include "gait_manager/posture.hpp"
#include "gait_manager/yaw.hpp"
#include "iceskate_native/controller.hpp"

namespace gait_manager
{

/// The enabled sources as a controller: posture a joint command with an impedance, the others
/// torques held over the control period. The head top's y at t = 0 (or at the first call) is
/// latched as the start of the walking stabiliser's pace point. GaitManagerError when a
/// command is not finite.
class GaitManagerController final : public iceskate_native::Controller
{
public:
  explicit GaitManagerController(GaitManagerParameters params);

  void compute(
    const iceskate_native::Observation & obs, iceskate_native::Kinematics & kinematics,
    iceskate_native::ControllerOutput & out) override;

  /// New parameters from the next call on.
  void set_parameters(GaitManagerParameters params);

  const GaitManagerParameters & parameters() const noexcept { return params_; }

  /// The head top's y [m] latched at t = 0 (or at the first call); nullopt before.
  std::optional<double> head_start_y() const noexcept { return head_start_y_; }

private:
  bool enabled(Source source) const { return params_.enabled[static_cast<std::size_t>(source)]; }

  GaitManagerParameters params_;
  std::optional<double> head_start_y_;
};

}  // namespace gait_manager
