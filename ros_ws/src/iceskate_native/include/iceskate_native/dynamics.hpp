// Constrained equations of motion of every Table 2 mode, the paper's eq. (7) (docs/model.md
// §4): for the active coordinates a and the active swing constraints J it solves
//
//   [ M_aa + F_sup   -(J^T + friction) ] [ qdd_a  ]   [ tau_a - h_a - D qd_a + ... ]
//   [ J               0                ] [ lambda ] = [ -Jdot qd                   ]
//
// with Coulomb friction on a sliding swing heel and on a gliding support foot (N_s from the
// vertical momentum balance), on Pinocchio's algorithms. The native counterpart of
// the Python formulation of the test oracle (tests/oracle/dynamics.py), tested against it.
// Units: SI (m, rad, s, kg, N, N m).
#pragma once

#include <array>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "iceskate_native/model.hpp"
#include "iceskate_native/modes.hpp"
#include "iceskate_native/saddle_point.hpp"

namespace iceskate_native
{

using Wrench = Eigen::Matrix<double, 6, 1>;

/// A model rooted at one support foot with one pivot edge (Table-2 coordinates, nq = nv = 18)
/// and the frames the dynamics uses by name (swing_heel, swing_toe, the links for pushes).
struct SupportModel
{
  RobotModel model;
  std::map<std::string, int> frames;

  /// The frame's index; std::invalid_argument for an unknown name.
  int frame(const std::string & name) const;
};

/// Physical options of the contact and joint model (iceskate_sim.model.dynamics.DynamicsParameters).
struct DynamicsParameters
{
  double mu = 0.005;               ///< Coulomb coefficient of a sliding foot
  double baumgarte = 0.0;          ///< Baumgarte constant of the swing constraints [1/s]
  bool joint_limits = true;        ///< soft stops on
  double limit_stiffness = 1.0e4;  ///< [N m/rad]
  double limit_damping = 100.0;    ///< [N m s/rad], while a stop is penetrated
  bool damping = true;             ///< Table 1's joint damping on
};

/// A soft joint stop: coordinate index and its range [rad].
struct JointLimit
{
  int index;
  double lower;
  double upper;
};

/// The discrete part of the state besides the mode: side 0 right / 1 left, pivot 0 toe /
/// 1 heel, the pinned heel's world y [m], the slide directions sgn(yd0) and sgn(yd_h).
struct Contact
{
  int mode = 1;
  int side = 0;
  int pivot = 0;
  double heel_anchor_y = 0.0;
  double support_slide_dir = 1.0;
  double heel_slide_dir = 1.0;
};

/// What acts besides the state: input torques, a joint impedance (adds -K q - B v; K q_ref is
/// part of tau), an external force at a frame's origin.
struct Inputs
{
  Vector18 tau = Vector18::Zero();
  bool has_impedance = false;
  Vector18 stiffness = Vector18::Zero();
  Vector18 damping = Vector18::Zero();
  std::string push_frame;  ///< frame the push acts at ('': none), e.g. "chest"
  Eigen::Vector3d push_force = Eigen::Vector3d::Zero();  ///< world [N]
};

/// The solution of eq. (7) at one state (iceskate_sim.model.dynamics.DynamicsResult).
struct DynamicsResult
{
  Vector18 qdd = Vector18::Zero();
  Eigen::Vector3d multipliers = Eigen::Vector3d::Zero();  ///< f_nz [N], f_ny [N], tau_n [N m]
  Wrench support_wrench = Wrench::Zero();  ///< (F, M) on the support foot at (x_s, y0, 0)
  double support_normal = 0.0;             ///< N_s [N]
  double support_friction = 0.0;         ///< F_y [N]
  double zmp_y = 0.0;                      ///< [m]; NaN if N_s <= 0
  double heel_friction = 0.0;              ///< [N]
  Vector18 applied = Vector18::Zero();     ///< inputs, damping and stops [N m, N]
  Eigen::Vector3d swing_heel = Eigen::Vector3d::Zero();           ///< [m]
  Eigen::Vector3d swing_heel_velocity = Eigen::Vector3d::Zero();  ///< [m/s]
  double swing_toe_z = 0.0;                                       ///< [m]
  Vector18 passive = Vector18::Zero();     ///< damping and soft stops [N m]
};

/// The world placement of a frame: position [m] and rotation (frame axes in world columns).
struct Placement
{
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
};

/// The active swing constraints at one posture (Dynamics::constraints).
struct ConstraintRows
{
  Eigen::MatrixXd rows;      ///< nc x 18, columns of locked coordinates 0
  Eigen::VectorXd position;  ///< C(q) [m, rad]
};

/// Eq. (7) at one state as a linear system in (qdd_a, lambda), and the held stiffness and damping
/// of the applied forces there (their derivatives by q and v are -stiffness, -damping): what a
/// linearly implicit step linearizes about.
struct LinearizedSystem
{
  SystemMatrix matrix;     ///< [[M + e0 a^T, C], [G, 0]], n + nc unknowns
  ActiveVector row_change;  ///< a (empty: the support does not glide)
  int n = 0;               ///< active coordinates
  int nc = 0;              ///< active constraints
  Vector18 stiffness = Vector18::Zero();  ///< impedance and engaged soft stops [N m/rad, N/m]
  Vector18 damping = Vector18::Zero();    ///< Table 1, impedance and engaged stops [N m s/rad]
};

struct StateTerms;  // the input-free terms of one state (in dynamics.cpp)

/// Eq. (7) of every mode on the four support models; keeps one Pinocchio workspace per model,
/// so an instance is not thread-safe (make one per thread).
class Dynamics
{
public:
  /// models: indexed side * 2 + pivot; damping: Table 1's, per coordinate [N m s/rad].
  Dynamics(
    std::array<SupportModel, 4> models, ModeTable modes, const Vector18 & damping,
    double total_mass, std::vector<JointLimit> limits, DynamicsParameters params);
  ~Dynamics();
  Dynamics(const Dynamics &) = delete;
  Dynamics & operator=(const Dynamics &) = delete;

  /// Eq. (7) of contact.mode at (q, v) under the inputs. Throws std::invalid_argument for bad
  /// input and NativeError for a rank-deficient constraint set or a singular or non-finite
  /// solution.
  DynamicsResult evaluate(
    const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs);

  /// Accelerations of a step of size h [s] with the joint, impedance and soft-stop damping
  /// taken implicitly: (M + h D) a = f - D v over the same constrained system.
  Vector18 implicit_acceleration(
    const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs,
    double h);

  /// The system of eq. (7) at (q, v) under the inputs (LinearizedSystem).
  /// A soft stop counts in the stiffness and damping where q or q + lookahead v [s] is past it.
  const LinearizedSystem & linearize(
    const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs,
    double lookahead);

  /// Joint damping and soft-stop torques of all coordinates [N m].
  Vector18 passive_forces(const Vector18 & q, const Vector18 & v) const;

  /// M(q) over the active coordinates of contact.mode (n x n, symmetric).
  Eigen::MatrixXd mass_matrix(const Contact & contact, const Vector18 & q);

  /// The active swing constraints at q: their rows J (nc x 18, locked columns 0) and their
  /// positions C(q) [m, rad] (heel height, heel y minus its anchor, sole pitch).
  ConstraintRows constraints(const Contact & contact, const Vector18 & q);

  /// World position of a named frame of the support model of `contact` [m].
  Eigen::Vector3d frame_position(const Contact & contact, const Vector18 & q,
                                 const std::string & frame);

  /// World placements of frames of the support model of `contact` after one
  /// forward-kinematics pass: placements[i] of frame index ids[i] (SupportModel::frame; the
  /// vector is resized).
  void frame_placements(const Contact & contact, const Vector18 & q,
                        const std::vector<int> & ids, std::vector<Placement> & placements);

  /// J^T f: the generalized force of a world force `force` [N] at a named frame's origin
  /// [N m, N]; entries of locked coordinates 0.
  Vector18 push_force(const Contact & contact, const Vector18 & q, const std::string & frame,
                      const Eigen::Vector3d & force);

  /// World-aligned linear velocity of a named frame [m/s].
  Eigen::Vector3d frame_velocity(const Contact & contact, const Vector18 & q, const Vector18 & v,
                                 const std::string & frame);

  /// The Pinocchio data of the support model of `contact` holding the passes of eq. (7)'s
  /// terms at (q, v), made again unless they are the last ones and no other pass has run on
  /// that data since: the joint placements (liMi, oMi), the joint Jacobians (J, world) and the
  /// joint velocities (v) of a CRBA in the world convention and the non-linear effects. For
  /// ModelKinematics::adopt; valid until the next call on this object.
  const pinocchio::Data & state_passes(const Contact & contact, const Vector18 & q,
                                       const Vector18 & v);

  const SupportModel & support_model(int side, int pivot) const;
  const Mode & mode(int number) const;
  const ModeTable & modes() const noexcept { return modes_; }
  const DynamicsParameters & parameters() const noexcept { return params_; }

private:
  struct Workspace;  // Pinocchio data and the assembled system (in dynamics.cpp)

  /// The input-free terms of (q, v) on support model k (two Pinocchio passes unless kept).
  const StateTerms & update_terms(int k, const Vector18 & q, const Vector18 & v);
  void assemble(
    const Contact & contact, const Vector18 & q, const Vector18 & v, const Inputs & inputs);
  void solve(const Contact & contact, const Vector18 & q, const Vector18 & v);
  Wrench support_wrench(
    const Contact & contact, const Vector18 & q, const Inputs & inputs,
    const DynamicsResult & result);
  bool limits_engaged(const Vector18 & q) const;
  /// The velocity-proportional terms an implicit step takes implicitly, and (if `stiffness`)
  /// the position-proportional ones: Table 1's damping, the commanded impedance, a soft stop's
  /// where q or q + lookahead v [s] is past it; none on y0.
  void held_terms(const Vector18 & q, const Vector18 & v, const Inputs & inputs, double lookahead,
                  Vector18 & damping, Vector18 * stiffness) const;
  /// The applied generalized forces at (q, v): passive, inputs, push (sets work's passive and
  /// engaged).
  Vector18 applied_forces(
    const Mode & mode, int k, const Vector18 & q, const Vector18 & v, const Inputs & inputs);

  std::array<SupportModel, 4> models_;
  ModeTable modes_;
  Vector18 damping_;
  double mass_;
  std::vector<JointLimit> limits_;
  DynamicsParameters params_;
  std::unique_ptr<Workspace> work_;
};

}  // namespace iceskate_native
