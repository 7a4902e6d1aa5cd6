#include "gait_manager/posture.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/SVD>

#include "gait_manager/errors.hpp"

namespace gait_manager
{

namespace
{

using iceskate_native::Frame;
using iceskate_native::Kinematics;
using iceskate_native::Observation;
using iceskate_native::stance_schedule;
using iceskate_native::Vector18;

constexpr int kYawJoint = 8;
constexpr double kPinvTolerance = 1e-10;  // relative to the largest singular value (numpy rcond)

/// Rotate a (y, z) vector by a pitch `angle` (about +x; positive tilts +z towards -y).
Eigen::Vector2d rot(double angle, const Eigen::Vector2d & v)
{
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * v[0] - s * v[1], s * v[0] + c * v[1]};
}

/// Pitch angle beta of a (y, z) vector: v = |v| (-sin beta, cos beta).
double angle(const Eigen::Vector2d & v) { return std::atan2(-v[0], v[1]); }

/// The support-leg geometry of the observed support model, (y, z) of each placement [m].
struct LegGeometry
{
  Eigen::Vector2d base;    // y0 joint at y0 = 0
  Eigen::Vector2d pivot;   // q1 joint relative to the base
  Eigen::Vector2d ankle;   // q2 joint relative to the pivot
  Eigen::Vector2d shank;   // q3 (knee) relative to the ankle
  Eigen::Vector2d thigh;   // q4 (hip) relative to the knee
  Eigen::Vector2d pelvis;  // pelvis_centre frame relative to the hip
};

LegGeometry geometry(const Observation & obs, const Kinematics & kinematics)
{
  const auto placement = [&](int joint) -> Eigen::Vector2d {
    return kinematics.joint_placement(obs.side, obs.pivot, joint).tail<2>();
  };
  return {placement(0), placement(1), placement(2), placement(3), placement(4),
          kinematics.frame_offset(obs.side, obs.pivot, Frame::kPelvisCentre).tail<2>()};
}

}  // namespace

Vector18 standing_posture(double bend)
{
  Vector18 q = Vector18::Zero();
  q.segment<6>(2) << -bend, 2.0 * bend, -bend, bend, -2.0 * bend, bend;
  return q;
}

Eigen::Vector2d hip_target(
  const Observation & obs, Kinematics & kinematics, const PostureParameters & params)
{
  const LegGeometry geo = geometry(obs, kinematics);
  const double a = params.bend;
  const Eigen::Vector2d flat_ankle =
    geo.base + Eigen::Vector2d(obs.q[0], 0.0) + geo.pivot + geo.ankle;
  const Eigen::Vector2d knee = flat_ankle + rot(-a, geo.shank);
  const Eigen::Vector2d hip = knee + rot(a, geo.thigh);
  const Eigen::Vector2d standing = hip + rot(0.0, geo.pelvis);
  return standing + stance_schedule(params).shift(obs);
}

Eigen::Vector3d support_leg_ik(
  const Observation & obs, Kinematics & kinematics, const PostureParameters & params,
  const Eigen::Vector2d & target)
{
  const LegGeometry geo = geometry(obs, kinematics);
  const double q1 = kinematics.mode(obs.mode).q1_active ? obs.q[1] : 0.0;
  const Eigen::Vector2d pivot = geo.base + Eigen::Vector2d(obs.q[0], 0.0) + geo.pivot;
  const Eigen::Vector2d ankle = pivot + rot(q1, geo.ankle);
  const Eigen::Vector2d hip = target - rot(params.pelvis_pitch, geo.pelvis);
  const Eigen::Vector2d d = hip - ankle;
  const double l2 = std::hypot(geo.shank[0], geo.shank[1]);
  const double l3 = std::hypot(geo.thigh[0], geo.thigh[1]);
  const double b2 = angle(geo.shank), b3 = angle(geo.thigh);
  const double cos_gamma = (d[0] * d[0] + d[1] * d[1] - l2 * l2 - l3 * l3) / (2.0 * l2 * l3);
  const double gamma = std::acos(std::min(std::max(cos_gamma, -1.0), 1.0));
  const double shank_dir =
    angle(d) - std::atan2(l3 * std::sin(gamma), l2 + l3 * std::cos(gamma));
  const double phi2 = shank_dir - b2;
  const double q3 = gamma - b3 + b2;
  return {phi2 - q1, q3, params.pelvis_pitch - phi2 - q3};
}

StanceReference stance_reference(
  const Observation & obs, Kinematics & kinematics, const PostureParameters & params)
{
  StanceReference out;
  out.q_ref = standing_posture(params.bend);
  out.q_ref[0] = obs.q[0];
  out.q_ref[1] = kinematics.mode(obs.mode).q1_active ? obs.q[1] : 0.0;
  if (params.reference != PostureReference::kMoving) {
    return out;
  }
  out.q_ref.segment<3>(2) =
    support_leg_ik(obs, kinematics, params, hip_target(obs, kinematics, params));
  out.head_offset = stance_schedule(params).shift(obs);
  return out;
}

void posture_command(
  const Observation & obs, Kinematics & kinematics, const PostureParameters & params,
  iceskate_native::JointCommand & out)
{
  if (params.null_space) {
    out.set_torque(posture_torque(obs, kinematics, params));
    return;
  }
  out.effort.setZero();
  out.stiffness.setZero();
  out.damping.setZero();
  out.reference.setZero();
  out.has_impedance = true;
  if (!params.joints.empty()) {
    const Vector18 q_ref = stance_reference(obs, kinematics, params).q_ref;
    for (int j : params.joints) {
      out.reference[j] = q_ref[j];
      out.stiffness[j] = params.stiffness;
      out.damping[j] = params.damping;
    }
  }
  if (params.gravity_compensation && !params.gravity_joints.empty()) {
    const Vector18 g = kinematics.gravity(obs.support(), obs.q);
    for (int j : params.gravity_joints) {
      out.effort[j] += g[j];
    }
  }
  out.stiffness[kYawJoint] += params.yaw_stiffness;
  out.damping[kYawJoint] += params.yaw_damping;
  if (!out.effort.allFinite() || !out.reference.allFinite()) {
    throw GaitManagerError("posture command is not finite at t = " + std::to_string(obs.t));
  }
}

Vector18 posture_torque(
  const Observation & obs, Kinematics & kinematics, const PostureParameters & params)
{
  Vector18 tau = Vector18::Zero();
  if (!params.joints.empty()) {
    const auto & joints = params.joints;
    const Vector18 q_ref = stance_reference(obs, kinematics, params).q_ref;
    Eigen::VectorXd pd =
      params.stiffness * (q_ref(joints) - obs.q(joints)) - params.damping * obs.v(joints);
    if (params.null_space) {  // pd - J_d^T (J_d^+)^T pd, J_d: J_H over the driven joints
      const Eigen::MatrixXd jd =
        kinematics.head_pose(obs.support(), obs.q).jacobian(Eigen::all, joints);
      const Eigen::JacobiSVD<Eigen::MatrixXd> svd(jd, Eigen::ComputeThinU | Eigen::ComputeThinV);
      const Eigen::VectorXd & s = svd.singularValues();
      const double cutoff = kPinvTolerance * (s.size() > 0 ? s.maxCoeff() : 0.0);
      const Eigen::VectorXd inverse = (s.array() > cutoff).select(s.array().inverse(), 0.0);
      const Eigen::MatrixXd pinv =
        svd.matrixV() * inverse.asDiagonal() * svd.matrixU().transpose();
      pd -= jd.transpose() * (pinv.transpose() * pd);
    }
    tau(joints) = pd;
  }
  if (params.gravity_compensation && !params.gravity_joints.empty()) {
    const Vector18 g = kinematics.gravity(obs.support(), obs.q);
    for (int j : params.gravity_joints) {
      tau[j] += g[j];
    }
  }
  tau[kYawJoint] -=
    params.yaw_stiffness * obs.q[kYawJoint] + params.yaw_damping * obs.v[kYawJoint];
  if (!tau.allFinite()) {
    throw GaitManagerError("posture torque is not finite at t = " + std::to_string(obs.t));
  }
  return tau;
}

}  // namespace gait_manager
