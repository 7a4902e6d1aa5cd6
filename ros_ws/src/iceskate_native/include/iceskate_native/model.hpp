// RobotModel: an immutable Pinocchio model owned by the native side.
//
// The models are built in Python (iceskate_sim.model.robot: the four support-rooted models are
// assembled joint by joint from the URDF's links, not parsed from a file), so the C++ side gets
// exactly those models by deserialising Pinocchio's binary archive of them
// (Python: model.saveToBinary(pinocchio.serialization.StreamBuffer) -> bytes; see
// iceskate_native.model_bytes). Only src/model.cpp includes Pinocchio's serialization headers
// (~20 s to compile); this header needs Pinocchio's forward declarations only.
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include <pinocchio/multibody/fwd.hpp>

namespace iceskate_native
{

class RobotModel
{
public:
  /// The model from Pinocchio's binary archive of a pinocchio::Model.
  /// Throws std::invalid_argument when the bytes are no such archive.
  static RobotModel from_bytes(std::string_view bytes);

  /// The Pinocchio model (include <pinocchio/multibody.hpp> to use it).
  const pinocchio::Model & pin() const noexcept { return *model_; }

  int nq() const noexcept;
  int nv() const noexcept;
  int njoints() const noexcept;
  const std::string & name() const noexcept;

private:
  explicit RobotModel(std::shared_ptr<const pinocchio::Model> model) noexcept;

  // Shared and const: copies are cheap, and a model is never modified after loading.
  std::shared_ptr<const pinocchio::Model> model_;
};

}  // namespace iceskate_native
