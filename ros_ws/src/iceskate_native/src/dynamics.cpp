#include "iceskate_native/dynamics.hpp"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <Eigen/LU>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>

#include "iceskate_native/errors.hpp"
#include "iceskate_native/saddle_point.hpp"

namespace iceskate_native
{

namespace
{

constexpr double kRankTolerance = 1e-10;  // Hadamard ratio below which the constraints are singular
constexpr auto kWorldAligned = pinocchio::LOCAL_WORLD_ALIGNED;

using ConstVector = Eigen::Ref<const Eigen::VectorXd>;  // selects Pinocchio's compiled algorithms

// Row of the world-aligned heel Jacobian and acceleration a constraint uses.
int row_of(Constraint c) { return c == Constraint::kHeelZ ? 2 : 1; }

// Whether coordinate i belongs to the chain q1..q7 whose sum is the swing sole's pitch.
bool in_leg_chain(int i) { return i >= 1 && i <= 7; }

}  // namespace

// The input-free terms of one state (q, v) of one support model: what eq. (7) and the support
// wrench need from Pinocchio before the inputs enter. Kept for the last state, so that solving
// again at the same state under other inputs (a control period's start, an implicit step) costs
// no Pinocchio pass. Two passes make them: CRBA (world convention: M, the joint Jacobians, the
// centroidal momentum matrix) and the non-linear effects (RNEA at zero acceleration: h + g, the
// velocities, the bias wrench at the root).
struct StateTerms
{
  int model = -1;  // side * 2 + pivot; -1: none yet
  Vector18 q = Vector18::Zero();
  Vector18 v = Vector18::Zero();
  Eigen::Matrix<double, kCoordinates, kCoordinates> mass;  // M(q), both triangles
  Vector18 nle;                                              // h(q, v) + g(q)
  Eigen::Matrix<double, 6, kCoordinates> heel_jacobian;     // world-aligned
  Eigen::Vector3d heel;
  Eigen::Vector3d heel_velocity;
  Eigen::Vector3d heel_acceleration;  // classical, of the velocity products (Jdot v)
  double toe_z = 0.0;
  // The root joint's wrench on the tree is bias + A_g qdd: bias (at zero acceleration, with
  // gravity; root frame), A_g the centroidal momentum matrix (world, moments about the com).
  pinocchio::Force bias = pinocchio::Force::Zero();
  Eigen::Matrix<double, 6, kCoordinates> momentum;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();  // world [m]
  pinocchio::SE3 root = pinocchio::SE3::Identity();  // world placement of the root joint
  double vertical_bias = 0.0;  // world z of the bias force: m (g + zdd_com at qdd = 0) [N]
};

struct Dynamics::Workspace
{
  StateTerms terms;
  std::vector<pinocchio::Data> data;  // one per support model
  Eigen::VectorXd q, v;               // Pinocchio's argument type
  LinearizedSystem linearized;
  pinocchio::Data::Matrix6x jacobian;
  int model = 0;  // side * 2 + pivot of the system assembled
  int n = 0;      // active coordinates
  int nc = 0;     // active constraints
  SystemMatrix A;
  ActiveVector row_change;  // a of A's first row, M + e0 a^T (empty: none)
  SystemMatrix factored;  // the matrix whose factors `saddle` (or `lu`) holds (none: empty)
  bool structured = false;  // factored as a saddle point (else by `lu`)
  SaddlePoint saddle;
  SystemVector b;
  SystemVector x;
  Eigen::PartialPivLU<SystemMatrix> lu;
  Vector18 applied;
  Vector18 passive;
  bool engaged = false;
  Eigen::Vector3d heel;
  Eigen::Vector3d heel_velocity;
  double toe_z = 0.0;
  // the q at which data[k].oMi were last computed: CRBA in the world convention and the
  // kinematics passes compute the joint placements alike (a local-convention CRBA does not)
  std::array<Vector18, 4> placed_q;
  std::array<bool, 4> placed{};
  // data[terms.model] still holds the joint placements, Jacobians and velocities of the terms'
  // passes (state_passes): no pass at another state has run on it since
  bool passes_intact = false;

  /// A kinematics pass at q (and v, for one with velocities) has run on data[k].
  void placed_at(int k, const Vector18 & at, const Vector18 * velocity = nullptr)
  {
    placed_q[static_cast<std::size_t>(k)] = at;
    placed[static_cast<std::size_t>(k)] = true;
    if (k == terms.model && (at != terms.q || (velocity != nullptr && *velocity != terms.v))) {
      passes_intact = false;
    }
  }

  /// A pass that leaves data[k]'s joint placements at no one state has run on it (a
  /// local-convention CRBA, a Jacobian of one chain at another state).
  void unplaced(int k)
  {
    placed[static_cast<std::size_t>(k)] = false;
    if (k == terms.model) {
      passes_intact = false;
    }
  }

  bool is_placed_at(int k, const Vector18 & at) const
  {
    return placed[static_cast<std::size_t>(k)] && placed_q[static_cast<std::size_t>(k)] == at;
  }
};

int SupportModel::frame(const std::string & name) const
{
  const auto it = frames.find(name);
  if (it == frames.end()) {
    throw std::invalid_argument("unknown frame '" + name + "' of the support model");
  }
  return it->second;
}

Dynamics::Dynamics(
  std::array<SupportModel, 4> models, ModeTable modes, const Vector18 & damping,
  double total_mass, std::vector<JointLimit> limits, DynamicsParameters params)
: models_(std::move(models)),
  modes_(std::move(modes)),
  damping_(params.damping ? damping : Vector18::Zero()),
  mass_(total_mass),
  limits_(std::move(limits)),
  params_(params),
  work_(std::make_unique<Workspace>())
{
  check_modes(modes_);
  // Room for the four Data up front: a reallocation would copy every Data built so far (deep
  // copies, and Eigen's copy of a never-used LLT member reads its uninitialised ComputationInfo,
  // which UBSan reports), so each Data is constructed in place, once.
  work_->data.reserve(models_.size());
  for (const auto & limit : limits_) {
    if (limit.index < 0 || limit.index >= kCoordinates || !(limit.lower <= limit.upper)) {
      throw std::invalid_argument("a joint limit needs an index in 0..17 and lower <= upper");
    }
  }
  for (const auto & support : models_) {
    if (support.model.nq() != kCoordinates || support.model.nv() != kCoordinates) {
      throw std::invalid_argument("a support model must have 18 coordinates (nq = nv = 18)");
    }
    support.frame("swing_heel");  // both needed: std::invalid_argument if missing
    support.frame("swing_toe");
    for (const auto & [name, id] : support.frames) {
      if (id < 0 || id >= static_cast<int>(support.model.pin().nframes)) {
        throw std::invalid_argument("frame index of '" + name + "' out of range");
      }
    }
    work_->data.emplace_back(support.model.pin());
  }
  work_->q.resize(kCoordinates);
  work_->v.resize(kCoordinates);
  work_->jacobian.setZero(6, kCoordinates);
}

Dynamics::~Dynamics() = default;

const SupportModel & Dynamics::support_model(int side, int pivot) const
{
  if (side < 0 || side > 1 || pivot < 0 || pivot > 1) {
    throw std::invalid_argument("side and pivot must be 0 or 1");
  }
  return models_[static_cast<std::size_t>(side * 2 + pivot)];
}

const Mode & Dynamics::mode(int number) const
{
  return mode_numbered(modes_, number);
}

bool Dynamics::limits_engaged(const Vector18 & q) const
{
  for (const auto & limit : limits_) {
    if (q[limit.index] < limit.lower || q[limit.index] > limit.upper) {
      return true;
    }
  }
  return false;
}

Vector18 Dynamics::passive_forces(const Vector18 & q, const Vector18 & v) const
{
  Vector18 force = -damping_.cwiseProduct(v);
  if (params_.joint_limits) {
    for (const auto & limit : limits_) {
      const double penetration = std::min(q[limit.index] - limit.lower, 0.0)
                                 + std::max(q[limit.index] - limit.upper, 0.0);
      const double engaged = penetration != 0.0 ? 1.0 : 0.0;
      force[limit.index] -= params_.limit_stiffness * penetration
                            + params_.limit_damping * v[limit.index] * engaged;
    }
  }
  return force;
}

const StateTerms & Dynamics::update_terms(int k, const Vector18 & q, const Vector18 & v)
{
  Workspace & w = *work_;
  StateTerms & terms = w.terms;
  if (terms.model == k && terms.q == q && terms.v == v) {
    return terms;
  }
  const SupportModel & support = models_[static_cast<std::size_t>(k)];
  const pinocchio::Model & model = support.model.pin();
  pinocchio::Data & data = w.data[static_cast<std::size_t>(k)];
  w.q = q;
  w.v = v;
  pinocchio::crba(model, data, ConstVector(w.q), pinocchio::Convention::WORLD);
  pinocchio::nonLinearEffects(model, data, ConstVector(w.q), ConstVector(w.v));
  w.placed_at(k, q);
  const auto heel = static_cast<pinocchio::FrameIndex>(support.frame("swing_heel"));
  const auto toe = static_cast<pinocchio::FrameIndex>(support.frame("swing_toe"));
  terms.model = k;
  terms.q = q;
  terms.v = v;
  terms.mass = data.M.selfadjointView<Eigen::Upper>();  // Pinocchio fills the upper triangle
  terms.nle = data.nle;
  terms.heel = pinocchio::updateFramePlacement(model, data, heel).translation();
  w.jacobian.setZero();
  pinocchio::getFrameJacobian(model, data, heel, kWorldAligned, w.jacobian);
  terms.heel_jacobian = w.jacobian;
  terms.heel_velocity = pinocchio::getFrameVelocity(model, data, heel, kWorldAligned).linear();
  // the heel joint's acceleration of the velocity products: the non-linear effects' one less
  // the (uniform) gravity acceleration they start from at the root
  const pinocchio::JointIndex joint = model.frames[heel].parentJoint;
  data.a[joint] = data.a_gf[joint] - data.oMi[joint].actInv(data.a_gf[0]);
  terms.heel_acceleration =
    pinocchio::getFrameClassicalAcceleration(model, data, heel, kWorldAligned).linear();
  terms.toe_z = pinocchio::updateFramePlacement(model, data, toe).translation()[2];
  terms.bias = data.f[1];
  terms.momentum = data.Ag;
  terms.com = data.com[0];
  terms.root = data.oMi[1];
  terms.vertical_bias = terms.root.act(terms.bias).linear()[2];
  w.passes_intact = true;
  return terms;
}

const pinocchio::Data & Dynamics::state_passes(
  const Contact & contact, const Vector18 & q, const Vector18 & v)
{
  const int k = contact.side * 2 + contact.pivot;
  Workspace & w = *work_;
  if (!w.passes_intact) {  // the terms may be kept, but other passes have moved their data
    w.terms.model = -1;
  }
  update_terms(k, q, v);
  return w.data[static_cast<std::size_t>(k)];
}

void Dynamics::assemble(
  const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs)
{
  const Mode & mode = this->mode(contact.mode);
  support_model(contact.side, contact.pivot);  // std::invalid_argument for a bad side or pivot
  for (int i : {kY0, kQ1}) {
    const bool locked = i == kY0 ? !mode.y0_active : !mode.q1_active;
    if (locked && v[i] != 0.0) {
      std::ostringstream message;
      message << "mode " << mode.number << " dynamics: locked coordinate " << i
              << " must have zero velocity, got " << v[i];
      throw std::invalid_argument(message.str());
    }
  }
  Workspace & w = *work_;
  w.model = contact.side * 2 + contact.pivot;
  const auto & act = mode.active;
  const int n = static_cast<int>(act.size());
  const int nc = static_cast<int>(mode.constraints.size());
  w.n = n;
  w.nc = nc;
  w.q = q;
  w.v = v;

  const StateTerms & terms = update_terms(w.model, q, v);
  w.heel = terms.heel;
  w.heel_velocity = terms.heel_velocity;
  w.toe_z = terms.toe_z;
  w.applied = applied_forces(mode, w.model, q, v, inputs);

  const int size = n + nc;
  w.A.setZero(size, size);
  w.b.setZero(size);
  w.A.topLeftCorner(n, n) = terms.mass(act, act);
  w.b.head(n) = w.applied(act) - terms.nle(act);
  const double mu = params_.mu;
  if (nc > 0) {
    const auto & jacobian = terms.heel_jacobian;
    const Eigen::Vector3d & acc = terms.heel_acceleration;
    double chain = 0.0;
    for (int i = 1; i <= 7; ++i) {
      chain += q[i];
    }
    for (int k = 0; k < nc; ++k) {
      const Constraint c = mode.constraints[static_cast<std::size_t>(k)];
      double rate = 0.0;
      for (int i = 0; i < n; ++i) {
        const int j = act[static_cast<std::size_t>(i)];
        const double entry =
          c == Constraint::kSoleFlat ? (in_leg_chain(j) ? 1.0 : 0.0) : jacobian(row_of(c), j);
        w.A(n + k, i) = entry;
        w.A(i, n + k) = -entry;  // the generalized-force direction -J^T
        rate += entry * v[j];
      }
      w.b[n + k] = c == Constraint::kHeelZ ? -acc[2] : c == Constraint::kHeelY ? -acc[1] : -0.0;
      if (params_.baumgarte != 0.0) {
        const double alpha = params_.baumgarte;
        const double position = c == Constraint::kHeelZ   ? w.heel[2]
                                : c == Constraint::kHeelY ? w.heel[1] - contact.heel_anchor_y
                                                          : chain;
        w.b[n + k] -= 2.0 * alpha * rate + alpha * alpha * position;
      }
    }
    if (mode.swing_sliding) {  // friction mu f_nz on the heel, against its velocity
      w.A.col(n).head(n) =
        (mu * contact.heel_slide_dir * jacobian(1, act) - w.A.row(n).head(n)).transpose();
    }
  }
  w.row_change.resize(0);
  if (mode.y0_active) {  // Q_sup = -mu s0 N_s, N_s = m (g + zdd_com) - f_nz
    const double k = mu * contact.support_slide_dir;
    // m zdd_com = row z of A_g qdd + its velocity products
    w.row_change = k * terms.momentum(2, act).transpose();
    w.A.row(0).head(n) += w.row_change.transpose();
    w.b[0] -= k * terms.vertical_bias;
    if (nc > 0) {
      w.A(0, n) -= k;
    }
  }

  if (nc > 0) {  // the constraint rows must have full rank (Hadamard ratio of their Gram)
    const Eigen::MatrixXd rows = w.A.block(n, 0, nc, n);
    const Eigen::MatrixXd gram = rows * rows.transpose();
    const Eigen::VectorXd diag = gram.diagonal();
    const double ratio = (diag.array() > 0.0).all() ? gram.determinant() / diag.prod() : 0.0;
    if (!(ratio >= kRankTolerance)) {
      std::ostringstream message;
      message << "mode " << mode.number << ": the swing constraints are rank-deficient at this "
              << "posture (Hadamard ratio " << ratio << "); the all-straight double-support "
              << "posture is singular (docs/model.md §4.5)";
      throw NativeError(message.str());
    }
  }
}

Vector18 Dynamics::applied_forces(
  const Mode & mode, int k, const Vector18 & q, const Vector18 & v, const Inputs & inputs)
{
  Workspace & w = *work_;
  w.engaged = params_.joint_limits && limits_engaged(q);
  w.passive = w.engaged ? passive_forces(q, v) : Vector18(-damping_.cwiseProduct(v));
  Vector18 applied = w.passive + inputs.tau;
  if (inputs.has_impedance) {
    applied -= inputs.stiffness.cwiseProduct(q) + inputs.damping.cwiseProduct(v);
  }
  if (!mode.q1_active) {
    applied[kQ1] = 0.0;
  }
  applied[kY0] = 0.0;
  if (!inputs.push_frame.empty()) {  // J^T f of the push, at this state
    const SupportModel & support = models_[static_cast<std::size_t>(k)];
    pinocchio::Data & data = w.data[static_cast<std::size_t>(k)];
    w.q = q;
    // all joints' Jacobians and placements by Pinocchio's compiled algorithm (its
    // computeFrameJacobian, the push frame's chain only, is not in the library for this
    // argument type and would be compiled here, the heaviest part of this file's build)
    pinocchio::computeJointJacobians(support.model.pin(), data, ConstVector(w.q));
    w.placed_at(k, q);
    w.jacobian.setZero();
    pinocchio::getFrameJacobian(
      support.model.pin(), data,
      static_cast<pinocchio::FrameIndex>(support.frame(inputs.push_frame)), kWorldAligned,
      w.jacobian);
    applied += w.jacobian.topRows<3>().transpose() * inputs.push_force;
  }
  return applied;
}

const LinearizedSystem & Dynamics::linearize(
  const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs,
  double lookahead)
{
  assemble(contact, q, v, inputs);
  Workspace & w = *work_;
  LinearizedSystem & out = w.linearized;
  out.matrix = w.A;
  out.row_change = w.row_change;
  out.n = w.n;
  out.nc = w.nc;
  held_terms(q, v, inputs, lookahead, out.damping, &out.stiffness);
  return out;
}

void Dynamics::held_terms(const Vector18 & q, const Vector18 & v, const Inputs & inputs,
                          double lookahead, Vector18 & damping, Vector18 * stiffness) const
{
  damping = damping_;
  if (stiffness != nullptr) {
    stiffness->setZero();
  }
  if (params_.joint_limits) {
    for (const auto & limit : limits_) {
      const double now = q[limit.index];
      const double ahead = now + lookahead * v[limit.index];
      if (now < limit.lower || now > limit.upper || ahead < limit.lower || ahead > limit.upper) {
        damping[limit.index] += params_.limit_damping;
        if (stiffness != nullptr) {
          (*stiffness)[limit.index] += params_.limit_stiffness;
        }
      }
    }
  }
  if (inputs.has_impedance) {
    damping += inputs.damping;
    if (stiffness != nullptr) {
      *stiffness += inputs.stiffness;
    }
  }
  damping[kY0] = 0.0;
  if (stiffness != nullptr) {
    (*stiffness)[kY0] = 0.0;
  }
}

void Dynamics::solve(const Contact & contact, const Vector18 & q, const Vector18 & v)
{
  Workspace & w = *work_;
  if (w.factored.rows() != w.A.rows() || w.factored != w.A) {  // e.g. the same state again
    w.structured = w.saddle.factor(w.A, w.n, w.nc, w.row_change);
    if (!w.structured) {  // e.g. an impedance with negative damping in an implicit step
      w.lu.compute(w.A);
    }
    w.factored = w.A;
  }
  if (w.structured) {
    w.saddle.solve(w.b, w.x);
  } else {
    if ((w.lu.matrixLU().diagonal().array() == 0.0).any()) {
      throw NativeError("mode " + std::to_string(contact.mode) + ": singular dynamics matrix");
    }
    w.x = w.lu.solve(w.b);
  }
  if (!w.x.allFinite()) {
    std::ostringstream message;
    message << "mode " << contact.mode << " dynamics: the solution is not finite (|v|max "
            << v.cwiseAbs().maxCoeff() << ", |q|max " << q.cwiseAbs().maxCoeff() << ")";
    throw NativeError(message.str());
  }
}

DynamicsResult Dynamics::evaluate(
  const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs)
{
  assemble(contact, q, v, inputs);
  solve(contact, q, v);
  const Workspace & w = *work_;
  const Mode & mode = this->mode(contact.mode);
  DynamicsResult r;
  r.qdd(mode.active) = w.x.head(w.n);
  const Constraint order[3] = {Constraint::kHeelZ, Constraint::kHeelY, Constraint::kSoleFlat};
  for (int k = 0; k < 3; ++k) {
    const int at = mode.multiplier_index(order[k]);
    r.multipliers[k] = at < 0 ? 0.0 : w.x[w.n + at];
  }
  r.heel_friction =
    mode.swing_sliding ? -params_.mu * contact.heel_slide_dir * r.multipliers[0] : 0.0;
  r.applied = w.applied;
  r.passive = w.passive;
  r.swing_heel = w.heel;
  r.swing_heel_velocity = w.heel_velocity;
  r.swing_toe_z = w.toe_z;
  r.support_wrench = support_wrench(contact, q, inputs, r);
  r.support_normal = r.support_wrench[2];
  r.support_friction = r.support_wrench[1];
  r.zmp_y = r.support_normal > 0.0 ? q[kY0] + r.support_wrench[3] / r.support_normal
                                   : std::numeric_limits<double>::quiet_NaN();
  return r;
}

Vector18 Dynamics::implicit_acceleration(
  const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs,
  double h)
{
  if (!(h > 0.0) || !std::isfinite(h)) {
    throw std::invalid_argument("the implicit step h must be a finite time > 0 s");
  }
  assemble(contact, q, v, inputs);
  Workspace & w = *work_;
  Vector18 implicit;
  held_terms(q, v, inputs, 0.0, implicit, nullptr);
  const auto & act = mode(contact.mode).active;
  w.A.diagonal().head(w.n) += h * implicit(act);
  solve(contact, q, v);
  Vector18 qdd = Vector18::Zero();
  qdd(act) = w.x.head(w.n);
  return qdd;
}

Eigen::MatrixXd Dynamics::mass_matrix(const Contact & contact, const Vector18 & q)
{
  const auto & act = mode(contact.mode).active;
  const pinocchio::Model & model = support_model(contact.side, contact.pivot).model.pin();
  Workspace & w = *work_;
  pinocchio::Data & data = w.data[static_cast<std::size_t>(contact.side * 2 + contact.pivot)];
  w.q = q;
  pinocchio::crba(model, data, ConstVector(w.q));
  w.unplaced(contact.side * 2 + contact.pivot);
  const Eigen::MatrixXd mass = data.M.selfadjointView<Eigen::Upper>();  // from its upper triangle
  return mass(act, act);
}

ConstraintRows Dynamics::constraints(const Contact & contact, const Vector18 & q)
{
  const Mode & m = mode(contact.mode);
  const auto nc = static_cast<Eigen::Index>(m.constraints.size());
  ConstraintRows out{Eigen::MatrixXd::Zero(nc, kCoordinates), Eigen::VectorXd::Zero(nc)};
  if (nc == 0) {
    return out;
  }
  const SupportModel & support = support_model(contact.side, contact.pivot);
  const pinocchio::Model & model = support.model.pin();
  Workspace & w = *work_;
  pinocchio::Data & data = w.data[static_cast<std::size_t>(contact.side * 2 + contact.pivot)];
  w.q = q;
  pinocchio::computeJointJacobians(model, data, ConstVector(w.q));
  w.placed_at(contact.side * 2 + contact.pivot, q);
  const auto heel = static_cast<pinocchio::FrameIndex>(support.frame("swing_heel"));
  w.jacobian.setZero();
  pinocchio::getFrameJacobian(model, data, heel, kWorldAligned, w.jacobian);
  const Eigen::Vector3d position = pinocchio::updateFramePlacement(model, data, heel).translation();
  for (Eigen::Index k = 0; k < nc; ++k) {
    const Constraint c = m.constraints[static_cast<std::size_t>(k)];
    if (c == Constraint::kSoleFlat) {
      out.rows.block<1, 7>(k, 1).setOnes();
      out.position[k] = q.segment<7>(1).sum();
    } else {
      out.rows.row(k) = w.jacobian.row(row_of(c));
      out.position[k] =
        c == Constraint::kHeelZ ? position[2] : position[1] - contact.heel_anchor_y;
    }
  }
  zero_locked_columns(m, out.rows);
  return out;
}

Eigen::Vector3d Dynamics::frame_position(
  const Contact & contact, const Vector18 & q, const std::string & frame)
{
  std::vector<Placement> placement;
  frame_placements(contact, q, {support_model(contact.side, contact.pivot).frame(frame)},
                   placement);
  return placement[0].translation;
}

void Dynamics::frame_placements(
  const Contact & contact, const Vector18 & q, const std::vector<int> & ids,
  std::vector<Placement> & placements)
{
  const SupportModel & support = support_model(contact.side, contact.pivot);
  const pinocchio::Model & model = support.model.pin();
  Workspace & w = *work_;
  const int k = contact.side * 2 + contact.pivot;
  pinocchio::Data & data = w.data[static_cast<std::size_t>(k)];
  if (!w.is_placed_at(k, q)) {  // e.g. the state the last eq. (7) terms were computed at
    w.q = q;
    pinocchio::forwardKinematics(model, data, ConstVector(w.q));
    w.placed_at(k, q);
  }
  placements.resize(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const pinocchio::SE3 & placement =
      pinocchio::updateFramePlacement(model, data, static_cast<pinocchio::FrameIndex>(ids[i]));
    placements[i] = {placement.translation(), placement.rotation()};
  }
}

Vector18 Dynamics::push_force(
  const Contact & contact, const Vector18 & q, const std::string & frame,
  const Eigen::Vector3d & force)
{
  const Mode & m = mode(contact.mode);
  const SupportModel & support = support_model(contact.side, contact.pivot);
  const pinocchio::Model & model = support.model.pin();
  Workspace & w = *work_;
  pinocchio::Data & data = w.data[static_cast<std::size_t>(contact.side * 2 + contact.pivot)];
  w.q = q;
  pinocchio::computeJointJacobians(model, data, ConstVector(w.q));
  w.placed_at(contact.side * 2 + contact.pivot, q);
  w.jacobian.setZero();
  pinocchio::getFrameJacobian(
    model, data, static_cast<pinocchio::FrameIndex>(support.frame(frame)), kWorldAligned,
    w.jacobian);
  Vector18 out = w.jacobian.topRows<3>().transpose() * force;
  zero_locked_columns(m, out.transpose());
  return out;
}

Eigen::Vector3d Dynamics::frame_velocity(
  const Contact & contact, const Vector18 & q, const Vector18 & v, const std::string & frame)
{
  const SupportModel & support = support_model(contact.side, contact.pivot);
  const pinocchio::Model & model = support.model.pin();
  Workspace & w = *work_;
  pinocchio::Data & data = w.data[static_cast<std::size_t>(contact.side * 2 + contact.pivot)];
  w.q = q;
  w.v = v;
  pinocchio::forwardKinematics(model, data, ConstVector(w.q), ConstVector(w.v));
  w.placed_at(contact.side * 2 + contact.pivot, q, &v);
  return pinocchio::getFrameVelocity(
           model, data, static_cast<pinocchio::FrameIndex>(support.frame(frame)), kWorldAligned)
    .linear();
}

Wrench Dynamics::support_wrench(
  const Contact & contact, const Vector18 & q, const Inputs & inputs,
  const DynamicsResult & result)
{
  // The wrench the root joint supplies for the motion (RNEA's, affine in qdd: the bias of the
  // state plus the momentum rate A_g qdd); the swing contact and a push supply part of it, the
  // support foot the rest (world-aligned: the y0 joint does not turn).
  Workspace & w = *work_;
  const StateTerms & terms = w.terms;
  const SupportModel & support = models_[static_cast<std::size_t>(w.model)];
  const pinocchio::Model & model = support.model.pin();
  pinocchio::Data & data = w.data[static_cast<std::size_t>(w.model)];
  const Wrench rate = terms.momentum * result.qdd;  // (force, moment about the com), world
  const Eigen::Vector3d rate_force = rate.head<3>();
  const pinocchio::Force at_origin(rate_force, rate.tail<3>() + terms.com.cross(rate_force));
  const pinocchio::Force root = terms.bias + terms.root.actInv(at_origin);
  Eigen::Vector3d force = root.linear();
  Eigen::Vector3d moment = root.angular();
  const Eigen::Vector3d origin = terms.root.translation();
  const auto minus_force_at = [&](const Eigen::Vector3d & r, const Eigen::Vector3d & p) {
    force -= p;
    moment -= r.cross(p);
  };
  if (w.nc > 0) {
    const Eigen::Vector3d swing(
      0.0, result.multipliers[1] + result.heel_friction, result.multipliers[0]);
    minus_force_at(result.swing_heel - origin, swing);
    moment[0] -= result.multipliers[2];
  }
  if (!inputs.push_frame.empty()) {  // (other queries may have moved data since the terms)
    w.q = q;
    pinocchio::forwardKinematics(model, data, ConstVector(w.q));
    w.placed_at(w.model, q);
    const auto frame = static_cast<pinocchio::FrameIndex>(support.frame(inputs.push_frame));
    const Eigen::Vector3d at = pinocchio::updateFramePlacement(model, data, frame).translation();
    minus_force_at(at - origin, inputs.push_force);
  }
  if (mode(contact.mode).q1_active) {
    moment[0] -= result.applied[kQ1];  // the input and damping at the floor hinge
  }
  Wrench wrench;
  wrench << force, moment;
  return wrench;
}

}  // namespace iceskate_native
