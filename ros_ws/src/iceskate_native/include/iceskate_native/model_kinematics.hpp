// ModelKinematics: the Kinematics interface (kinematics.hpp) on Pinocchio, over the same four
// support models and mode table the Dynamics kernel gets, with a pinocchio::Data of its own per
// model (the laws never disturb the dynamics' workspaces); its answers equal those of
// iceskate_sim.model.dynamics.ModelTerms on the same Pinocchio models. It keeps
// each support model's answers at the last state asked, so the many queries of one control
// instant cost one Pinocchio pass of each kind.
#pragma once

#include <array>
#include <memory>

#include "iceskate_native/dynamics.hpp"
#include "iceskate_native/kinematics.hpp"

namespace iceskate_native
{

struct StateCache;  // one support model's answers at one state (in model_kinematics.cpp)

class ModelKinematics final : public Kinematics
{
public:
  /// models: indexed side * 2 + pivot, each with the frames head_top, swing_heel, support_toe
  /// and pelvis_centre and the joints y0, q1..q17; total_mass [kg]. std::invalid_argument for
  /// a missing frame or joint or a bad mode table.
  ModelKinematics(std::array<SupportModel, 4> models, ModeTable modes, double total_mass);
  ~ModelKinematics() override;
  ModelKinematics(const ModelKinematics &) = delete;
  ModelKinematics & operator=(const ModelKinematics &) = delete;

  /// Take the joint placements, Jacobians and velocities of support model (side, pivot) at
  /// (q, v) from `passes` (Dynamics::state_passes at the same state, whose passes compute them
  /// alike) instead of running the two passes that make them: the answers stay the same to
  /// the bit. They serve the queries at that state until another state is asked.
  void adopt(int side, int pivot, const Vector18 & q, const Vector18 & v,
             const pinocchio::Data & passes);

  /// Whether adopt() may take the passes of `dynamics`: its four support models equal these
  /// (pinocchio::Model equality), and every joint is revolute or prismatic, whose motion
  /// subspace does not depend on q (adopt() does not copy the joints' data).
  bool can_adopt_from(const Dynamics & dynamics) const;

  const Mode & mode(int number) const override;
  double total_mass() const override { return mass_; }
  Eigen::Vector3d joint_placement(int side, int pivot, int joint) const override;
  Eigen::Vector3d frame_offset(int side, int pivot, Frame frame) const override;
  HeadPose head_pose(const SupportState & state, const Vector18 & q) override;
  Vector18 gravity(const SupportState & state, const Vector18 & q) override;
  Vector18 swing_heel_z_row(const SupportState & state, const Vector18 & q) override;
  CentreOfMass centre_of_mass(const SupportState & state, const Vector18 & q,
                              const Vector18 & v) override;
  Eigen::Vector3d frame_position(const SupportState & state, const Vector18 & q,
                                 Frame frame) override;
  Eigen::Vector3d joint_position(const SupportState & state, const Vector18 & q,
                                 int joint) override;
  Eigen::Vector3d joint_velocity(const SupportState & state, const Vector18 & q,
                                 const Vector18 & v, int joint) override;

private:
  struct Workspace;  // Pinocchio data, answers and argument buffers (in model_kinematics.cpp)

  std::size_t model_index(int side, int pivot) const;
  /// Model k's answers, emptied unless they are at q (and v).
  StateCache & at(std::size_t k, const Vector18 & q);
  StateCache & at(std::size_t k, const Vector18 & q, const Vector18 & v);
  /// Model k's answers at q with the position-level ones computed (one joint-Jacobian pass).
  const StateCache & positions(std::size_t k, const Vector18 & q);
  /// Model k's answers at (q, v) with the velocity-level ones computed (the joint velocities,
  /// the centre of mass and its Jacobian: one forward pass).
  const StateCache & velocities(std::size_t k, const Vector18 & q, const Vector18 & v);

  std::array<SupportModel, 4> models_;
  ModeTable modes_;
  double mass_;
  std::unique_ptr<Workspace> work_;
};

}  // namespace iceskate_native
