#include "iceskate_native/model_kinematics.hpp"

#include <array>
#include <cmath>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/multibody.hpp>

namespace iceskate_native
{

namespace
{

constexpr auto kWorldAligned = pinocchio::LOCAL_WORLD_ALIGNED;
constexpr int kFrames = static_cast<int>(kFrameNames.size());

using ConstVector = Eigen::Ref<const Eigen::VectorXd>;  // selects Pinocchio's compiled algorithms

std::string joint_name(int joint) { return joint == kY0 ? "y0" : "q" + std::to_string(joint); }

void check_joint(int joint)
{
  if (joint < 0 || joint >= kCoordinates) {
    throw std::invalid_argument(
      "joint " + std::to_string(joint) + " out of range: joints are numbered 0 (y0) to 17");
  }
}

}  // namespace

// One support model's answers at the last posture (and velocity) asked: the laws of one control
// instant ask the same state many times (the head pose twice, the centre of mass twice, a frame
// or joint position four times), so each Pinocchio pass runs once per state and model.
struct StateCache
{
  Vector18 q = Vector18::Zero();
  Vector18 v = Vector18::Zero();
  bool has_q = false;  // q holds the posture of the answers below
  bool has_v = false;  // v holds the velocity of the velocity-level answers
  bool placed = false;  // the data holds the joint placements and Jacobians at q
  bool moving = false;  // the data holds the joint placements and velocities at (q, v)
  bool positions = false;  // joints, frames, head, heel_z_row
  std::array<Eigen::Vector3d, kCoordinates> joints;  // world positions [m]
  std::array<Eigen::Vector3d, kFrames> frames;       // world positions [m], Frame's order
  HeadPose head;                                     // columns of locked coordinates kept
  Vector18 heel_z_row = Vector18::Zero();            // idem
  bool gravity = false;
  Vector18 g = Vector18::Zero();  // every coordinate
  bool velocities = false;  // centre, joint_velocities
  CentreOfMass centre;
  std::array<Eigen::Vector3d, kCoordinates> joint_velocities;  // world-aligned [m/s]
};

namespace
{

/// The generalized gravity g(q) = -m J_com^T g0 from the centre of mass's Jacobian in `data`
/// (what a gravity pass computes, in one product: the laws need that Jacobian anyway).
void keep_gravity(const pinocchio::Model & model, const pinocchio::Data & data, StateCache & c)
{
  c.g = -data.mass[0] * (data.Jcom.transpose() * model.gravity.linear());
  c.gravity = true;
}

}  // namespace

struct ModelKinematics::Workspace
{
  std::vector<pinocchio::Data> data;  // one per support model
  std::array<StateCache, 4> cache;    // one per support model
  // Pinocchio indices per model: joint of coordinate i, and the frames in Frame's order
  std::array<std::array<pinocchio::JointIndex, kCoordinates>, 4> joints{};
  std::array<std::array<pinocchio::FrameIndex, kFrames>, 4> frames{};
  Eigen::VectorXd q, v;  // Pinocchio's argument type
  pinocchio::Data::Matrix6x jacobian;
};

ModelKinematics::ModelKinematics(
  std::array<SupportModel, 4> models, ModeTable modes, double total_mass)
: models_(std::move(models)),
  modes_(std::move(modes)),
  mass_(total_mass),
  work_(std::make_unique<Workspace>())
{
  check_modes(modes_);
  if (!(total_mass > 0.0) || !std::isfinite(total_mass)) {
    throw std::invalid_argument("total_mass must be a finite mass > 0 kg");
  }
  Workspace & w = *work_;
  w.data.reserve(models_.size());  // each Data built in place once (see Dynamics)
  for (std::size_t k = 0; k < models_.size(); ++k) {
    const SupportModel & support = models_[k];
    const pinocchio::Model & model = support.model.pin();
    if (support.model.nq() != kCoordinates || support.model.nv() != kCoordinates) {
      throw std::invalid_argument("a support model must have 18 coordinates (nq = nv = 18)");
    }
    for (int i = 0; i < kCoordinates; ++i) {
      const std::string name = joint_name(i);
      if (!model.existJointName(name)) {
        throw std::invalid_argument("support model '" + model.name + "' has no joint " + name);
      }
      w.joints[k][static_cast<std::size_t>(i)] = model.getJointId(name);
    }
    for (int f = 0; f < kFrames; ++f) {
      const char * name = kFrameNames[static_cast<std::size_t>(f)];
      const int id = support.frame(name);
      if (id < 0 || id >= static_cast<int>(model.nframes)) {
        throw std::invalid_argument(std::string("frame index of '") + name + "' out of range");
      }
      w.frames[k][static_cast<std::size_t>(f)] = static_cast<pinocchio::FrameIndex>(id);
    }
    w.data.emplace_back(model);
  }
  w.q.resize(kCoordinates);
  w.v.resize(kCoordinates);
  w.jacobian.setZero(6, kCoordinates);
}

ModelKinematics::~ModelKinematics() = default;

std::size_t ModelKinematics::model_index(int side, int pivot) const
{
  if (side < 0 || side > 1 || pivot < 0 || pivot > 1) {
    throw std::invalid_argument("side and pivot must be 0 or 1");
  }
  return static_cast<std::size_t>(side * 2 + pivot);
}

const Mode & ModelKinematics::mode(int number) const
{
  return mode_numbered(modes_, number);
}

Eigen::Vector3d ModelKinematics::joint_placement(int side, int pivot, int joint) const
{
  check_joint(joint);
  const auto k = model_index(side, pivot);
  return models_[k].model.pin().jointPlacements[work_->joints[k][static_cast<std::size_t>(joint)]]
    .translation();
}

Eigen::Vector3d ModelKinematics::frame_offset(int side, int pivot, Frame frame) const
{
  const auto k = model_index(side, pivot);
  return models_[k].model.pin().frames[work_->frames[k][static_cast<std::size_t>(frame)]]
    .placement.translation();
}

StateCache & ModelKinematics::at(std::size_t k, const Vector18 & q)
{
  StateCache & c = work_->cache[k];
  if (!c.has_q || c.q != q) {
    c = StateCache{};
    c.q = q;
    c.has_q = true;
  }
  return c;
}

StateCache & ModelKinematics::at(std::size_t k, const Vector18 & q, const Vector18 & v)
{
  StateCache & c = at(k, q);
  if (!c.has_v || c.v != v) {
    c.v = v;
    c.has_v = true;
    c.velocities = false;
    c.moving = false;
  }
  return c;
}

const StateCache & ModelKinematics::positions(std::size_t k, const Vector18 & q)
{
  StateCache & c = at(k, q);
  if (c.positions) {
    return c;
  }
  const pinocchio::Model & model = models_[k].model.pin();
  Workspace & w = *work_;
  pinocchio::Data & data = w.data[k];
  if (!c.placed) {
    w.q = q;
    pinocchio::computeJointJacobians(model, data, ConstVector(w.q));
    c.placed = true;
  }
  for (std::size_t i = 0; i < kCoordinates; ++i) {
    c.joints[i] = data.oMi[w.joints[k][i]].translation();
  }
  for (std::size_t f = 0; f < kFrames; ++f) {
    c.frames[f] = pinocchio::updateFramePlacement(model, data, w.frames[k][f]).translation();
  }
  const auto head = w.frames[k][static_cast<std::size_t>(Frame::kHeadTop)];
  const pinocchio::SE3 & placement = data.oMf[head];
  w.jacobian.setZero();
  pinocchio::getFrameJacobian(model, data, head, kWorldAligned, w.jacobian);
  const Eigen::Matrix3d & rotation = placement.rotation();
  const double zx = rotation(0, 2), zy = rotation(1, 2), zz = rotation(2, 2);
  const double denom = zy * zy + zz * zz;
  const Eigen::RowVector3d pitch(1.0, -zx * zy / denom, -zx * zz / denom);
  c.head.psi << placement.translation()[1], placement.translation()[2],
    std::atan2(-rotation(1, 2), rotation(2, 2));
  c.head.jacobian.row(0) = w.jacobian.row(1);
  c.head.jacobian.row(1) = w.jacobian.row(2);
  c.head.jacobian.row(2) = pitch * w.jacobian.bottomRows<3>();
  w.jacobian.setZero();
  pinocchio::getFrameJacobian(model, data, w.frames[k][static_cast<std::size_t>(
                                Frame::kSwingHeel)], kWorldAligned, w.jacobian);
  c.heel_z_row = w.jacobian.row(2).transpose();
  c.positions = true;
  return c;
}

void ModelKinematics::adopt(
  int side, int pivot, const Vector18 & q, const Vector18 & v, const pinocchio::Data & passes)
{
  const auto k = model_index(side, pivot);
  StateCache & c = at(k, q, v);
  if (c.placed && c.moving) {
    return;
  }
  pinocchio::Data & data = work_->data[k];
  data.liMi = passes.liMi;
  data.oMi = passes.oMi;
  data.J = passes.J;
  data.v = passes.v;
  c.placed = true;
  c.moving = true;
}

bool ModelKinematics::can_adopt_from(const Dynamics & dynamics) const
{
  static const std::set<std::string> kConstantSubspace = {
    "JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned",
    "JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"};
  for (std::size_t k = 0; k < models_.size(); ++k) {
    const pinocchio::Model & own = models_[k].model.pin();
    const pinocchio::Model & theirs =
      dynamics.support_model(static_cast<int>(k) / 2, static_cast<int>(k) % 2).model.pin();
    if (!(own == theirs)) {
      return false;
    }
    for (pinocchio::JointIndex i = 1; i < own.joints.size(); ++i) {
      if (kConstantSubspace.count(own.joints[i].shortname()) == 0) {
        return false;
      }
    }
  }
  return true;
}

HeadPose ModelKinematics::head_pose(const SupportState & state, const Vector18 & q)
{
  const Mode & m = mode(state.mode);
  HeadPose pose = positions(model_index(state.side, state.pivot), q).head;
  zero_locked_columns(m, pose.jacobian);
  return pose;
}

Vector18 ModelKinematics::gravity(const SupportState & state, const Vector18 & q)
{
  const Mode & m = mode(state.mode);
  const auto k = model_index(state.side, state.pivot);
  StateCache & c = at(k, q);
  if (!c.gravity) {
    const pinocchio::Model & model = models_[k].model.pin();
    Workspace & w = *work_;
    w.q = q;  // Pinocchio's compiled algorithm: see velocities()
    pinocchio::jacobianCenterOfMass(model, w.data[k], ConstVector(w.q));
    keep_gravity(model, w.data[k], c);
  }
  Vector18 out = Vector18::Zero();
  out(m.active) = c.g(m.active);
  return out;
}

Vector18 ModelKinematics::swing_heel_z_row(const SupportState & state, const Vector18 & q)
{
  const Mode & m = mode(state.mode);
  Vector18 row = positions(model_index(state.side, state.pivot), q).heel_z_row;
  zero_locked_columns(m, row.transpose());
  return row;
}

CentreOfMass ModelKinematics::centre_of_mass(
  const SupportState & state, const Vector18 & q, const Vector18 & v)
{
  return velocities(model_index(state.side, state.pivot), q, v).centre;
}

Eigen::Vector3d ModelKinematics::frame_position(
  const SupportState & state, const Vector18 & q, Frame frame)
{
  return positions(model_index(state.side, state.pivot), q)
    .frames[static_cast<std::size_t>(frame)];
}

Eigen::Vector3d ModelKinematics::joint_position(
  const SupportState & state, const Vector18 & q, int joint)
{
  check_joint(joint);
  return positions(model_index(state.side, state.pivot), q)
    .joints[static_cast<std::size_t>(joint)];
}

Eigen::Vector3d ModelKinematics::joint_velocity(
  const SupportState & state, const Vector18 & q, const Vector18 & v, int joint)
{
  check_joint(joint);
  return velocities(model_index(state.side, state.pivot), q, v)
    .joint_velocities[static_cast<std::size_t>(joint)];
}

const StateCache & ModelKinematics::velocities(
  std::size_t k, const Vector18 & q, const Vector18 & v)
{
  StateCache & c = at(k, q, v);
  if (c.velocities) {
    return c;
  }
  const pinocchio::Model & model = models_[k].model.pin();
  Workspace & w = *work_;
  pinocchio::Data & data = w.data[k];
  w.q = q;
  if (!c.moving) {
    w.v = v;
    // one forward pass for the joint velocities and the centre of mass's velocity (what
    // centerOfMass(q, v) would run again at the same state)
    pinocchio::forwardKinematics(model, data, ConstVector(w.q), ConstVector(w.v));
    c.moving = true;
  }
  for (std::size_t i = 0; i < kCoordinates; ++i) {
    c.joint_velocities[i] =
      pinocchio::getVelocity(model, data, w.joints[k][i], kWorldAligned).linear();
  }
  pinocchio::centerOfMass(model, data, pinocchio::VELOCITY);
  c.centre.position = data.com[0];
  c.centre.velocity = data.vcom[0];
  // Pinocchio's compiled jacobianCenterOfMass(q) runs one more placement pass; the form without
  // q (the placements as they are) is not in its library and would be compiled here, the
  // heaviest part of this file's build
  c.centre.jacobian_y =
    pinocchio::jacobianCenterOfMass(model, data, ConstVector(w.q)).row(1).transpose();
  if (!c.gravity) {
    keep_gravity(model, data, c);
  }
  c.velocities = true;
  return c;
}

}  // namespace iceskate_native
