// The module gait_manager._law: GaitManagerController, the C++ sources as an
// iceskate_native.Controller (the base type comes from iceskate_native, imported first), built
// from a GaitManagerParameters object (the one schema); a bad field is a ValueError naming it,
// a command that is not finite a gait_manager.errors.GaitManagerError.
#include <exception>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <utility>

#include <nanobind/nanobind.h>
#include <nanobind/stl/optional.h>

#include "gait_manager/errors.hpp"
#include "gait_manager/law.hpp"
#include "iceskate_native/binding_parameters.hpp"
#include "iceskate_native/controller.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace
{

using iceskate_native::binding::Fields;
namespace gm = gait_manager;

constexpr int kLastJoint = iceskate_native::kCoordinates - 1;

gm::PhaseReading phase_of(const Fields & block)
{
  return block.choice<gm::PhaseReading>(
    "phase", {{"A", gm::PhaseReading::kA},
              {"B", gm::PhaseReading::kB},
              {"B_clipped", gm::PhaseReading::kBClipped}});
}

iceskate_native::StanceSchedule stance_of(const Fields & block)
{
  return {block.number("shift_y1"), block.number("shift_z1"), block.number("shift_time1"),
          block.number("shift_y2"), block.number("shift_time2")};
}

gm::PostureParameters posture_of(const Fields & f)
{
  gm::PostureParameters p;
  p.reference = f.choice<gm::PostureReference>(
    "reference", {{"moving", gm::PostureReference::kMoving},
                  {"standing", gm::PostureReference::kStanding},
                  {"balance", gm::PostureReference::kBalance}});
  p.joints = f.joints("joints", 2, kLastJoint);
  p.stiffness = f.number("stiffness");
  p.damping = f.number("damping");
  p.gravity_compensation = f.flag("gravity_compensation");
  p.gravity_joints = f.joints("gravity_joints", 2, kLastJoint);
  p.yaw_stiffness = f.number("yaw_stiffness");
  p.yaw_damping = f.number("yaw_damping");
  p.null_space = f.flag("null_space");
  p.bend = f.number("bend");
  p.pelvis_pitch = f.number("pelvis_pitch");
  p.stance = stance_of(f);
  return p;
}

gm::BalanceParameters balance_of(const Fields & f)
{
  gm::BalanceParameters p;
  for (auto [name, field] : std::initializer_list<std::pair<const char *, double *>>{
         {"swing_time", &p.swing_time},
         {"glide_time", &p.glide_time},
         {"clearance", &p.clearance},
         {"press", &p.press},
         {"lift_fraction", &p.lift_fraction},
         {"descent_start", &p.descent_start},
         {"step_length", &p.step_length},
         {"placement_gain", &p.placement_gain},
         {"speed", &p.speed},
         {"speed_gain", &p.speed_gain},
         {"pace_gain", &p.pace_gain},
         {"feedback_limit", &p.feedback_limit},
         {"drive", &p.drive},
         {"max_force", &p.max_force},
         {"max_brake", &p.max_brake},
         {"com_stiffness", &p.com_stiffness},
         {"com_damping", &p.com_damping},
         {"com_offset", &p.com_offset},
         {"stance_knee", &p.stance_knee},
         {"trunk", &p.trunk},
         {"stiffness", &p.stiffness},
         {"ankle_stiffness", &p.ankle_stiffness},
         {"ankle_damping", &p.ankle_damping},
         {"swing_stiffness", &p.swing_stiffness},
         {"swing_damping", &p.swing_damping},
         {"front_hip_stiffness", &p.front_hip_stiffness},
         {"front_knee_stiffness", &p.front_knee_stiffness},
         {"push", &p.push},
         {"push_ramp", &p.push_ramp},
         {"toe_off_flex", &p.toe_off_flex},
         {"blend", &p.blend},
         {"front_knee_step", &p.front_knee_step}}) {
    *field = f.number(name);
  }
  return p;
}

gm::FeedforwardParameters feedforward_of(const Fields & f)
{
  return {f.number("hip_amplitude"), f.number("hip_duration"), f.number("knee_amplitude"),
          f.number("knee_duration"), f.number("knee_stiffness"), f.number("knee_reference"),
          f.number("knee_damping"), f.number("ankle_push"), f.number("knee_push"),
          f.number("pivot_push"), f.flag("joint1_torque")};
}

gm::WeightTransferParameters weight_transfer_of(const Fields & f)
{
  return {f.number("share"), f.number("ramp_time"), f.number("moment_arm"),
          f.flag("joint1_torque"), f.number("start_share"), f.number("start_ramp"),
          f.choice<gm::WeightRule>("rule", {{"ramp", gm::WeightRule::kRamp},
                                            {"com", gm::WeightRule::kCom}}),
          f.number("capture_gain"), f.number("share_min"), f.number("heel_share")};
}

gm::Parameters parameters_of(nb::handle object)
{
  const Fields fields(object);
  gm::Parameters p;
  p.posture = posture_of(fields.block("posture"));
  p.balance = balance_of(fields.block("balance"));
  p.feedforward = feedforward_of(fields.block("feedforward"));
  p.weight_transfer = weight_transfer_of(fields.block("weight_transfer"));
  const Fields heel = fields.block("heel");
  p.heel = {heel.number("stiffness"), heel.number("damping"), heel.number("landing_pitch"),
            heel.number("ramp_time"), heel.number("contact_stiffness"),
            heel.number("contact_damping")};
  const Fields arm = fields.block("arm_assist");
  p.arm_assist = {arm.number("amplitude"), arm.number("period"), phase_of(arm),
                  arm.number("stiffness"), arm.number("damping"),
                  arm.integer("off_from_step_index", 0), arm.number("release_time"),
                  arm.number("release_damping")};
  const Fields yaw = fields.block("yaw");
  p.yaw = {yaw.number("amplitude"), yaw.number("period"), phase_of(yaw)};
  for (const auto & name : fields.texts("enabled")) {
    std::size_t k = 0;
    while (k < gm::kSources && name != gm::kSourceNames[k]) {
      ++k;
    }
    if (k == gm::kSources) {
      throw std::invalid_argument("enabled holds '" + name + "', which is no gait-manager "
                                  "source (posture, feedforward, weight_transfer, heel, "
                                  "arm_assist, yaw)");
    }
    p.enabled[k] = true;
  }
  return p;
}

}  // namespace

NB_MODULE(_law, m)
{
  m.doc() = "The gait-manager sources in C++ as an iceskate_native.Controller.";
  nb::module_::import_("iceskate_native");  // registers the base type Controller
  const nb::object error = nb::module_::import_("gait_manager.errors").attr("GaitManagerError");
  nb::register_exception_translator(
    [](const std::exception_ptr & p, void * payload) {
      try {
        std::rethrow_exception(p);
      } catch (const gm::GaitManagerError & e) {
        PyErr_SetString(static_cast<PyObject *>(payload), e.what());
      }
    },
    error.inc_ref().ptr());

  using gm::GaitManagerController;
  nb::class_<GaitManagerController, iceskate_native::Controller>(
    m, "GaitManagerController",
    "The enabled gait-manager sources (posture, feedforward, weight_transfer, heel, arm_assist, "
    "yaw, in that order); GaitManagerError when a command is not finite.")
    .def(
      "__init__",
      [](GaitManagerController * self, nb::handle params) {
        new (self) GaitManagerController(parameters_of(params));
      },
      "params"_a, "From a GaitManagerParameters; ValueError for a bad field.")
    .def(
      "set_parameters",
      [](GaitManagerController & self, nb::handle params) {
        self.set_parameters(parameters_of(params));
      },
      "params"_a, "New parameters from the next observation on (the pace point's start stays).")
    .def_prop_ro(
      "head_start_y", &GaitManagerController::head_start_y,
      "The head top's y [m] at t = 0 (or at the first observation), the start of the walking "
      "stabiliser's pace point; None before.");
}
