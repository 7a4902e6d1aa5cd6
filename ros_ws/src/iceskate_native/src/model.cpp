// The one translation unit that includes Pinocchio's serialization (boost::archive) headers:
// ~20 s of compile time, paid here only. Keep everything else out of this file.
#include "iceskate_native/model.hpp"

#include <algorithm>
#include <exception>
#include <stdexcept>
#include <string>
#include <utility>

#include <pinocchio/multibody.hpp>
#include <pinocchio/serialization.hpp>

namespace iceskate_native
{

RobotModel::RobotModel(std::shared_ptr<const pinocchio::Model> model) noexcept
: model_(std::move(model))
{
}

RobotModel RobotModel::from_bytes(std::string_view bytes)
{
  if (bytes.empty()) {
    throw std::invalid_argument("model bytes are empty: expected Pinocchio's binary archive of a "
                                "pinocchio.Model (iceskate_native.model_bytes(model))");
  }
  auto model = std::make_shared<pinocchio::Model>();
  try {
    pinocchio::serialization::StaticBuffer buffer(bytes.size());
    std::copy(bytes.begin(), bytes.end(), buffer.data());
    model->loadFromBinary(buffer);
  } catch (const std::exception & error) {
    // boost::archive::archive_exception (bad signature, truncated stream), std::bad_alloc from a
    // garbage length field, ...: all mean the bytes are not a model archive.
    throw std::invalid_argument(
      std::string("model bytes are not Pinocchio's binary archive of a pinocchio.Model (")
      + error.what() + ")");
  }
  const bool consistent = model->njoints >= 1
    && model->parents.size() == static_cast<std::size_t>(model->njoints)
    && model->joints.size() == static_cast<std::size_t>(model->njoints)
    && model->inertias.size() == static_cast<std::size_t>(model->njoints) && model->nq >= 0
    && model->nv >= 0;
  if (!consistent) {
    throw std::invalid_argument("model bytes decode to an inconsistent pinocchio.Model");
  }
  return RobotModel(std::move(model));
}

int RobotModel::nq() const noexcept { return model_->nq; }
int RobotModel::nv() const noexcept { return model_->nv; }
int RobotModel::njoints() const noexcept { return model_->njoints; }
const std::string & RobotModel::name() const noexcept { return model_->name; }

}  // namespace iceskate_native
