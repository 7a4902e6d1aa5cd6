#include "iceskate_native/checks.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace iceskate_native
{

void require_finite_vector(
  const Eigen::Ref<const Eigen::VectorXd> & value, Eigen::Index expected, const char * name,
  const char * what)
{
  if (value.size() != expected) {
    std::ostringstream message;
    message << name << " has " << value.size() << " entries, expected " << expected << " ("
            << what << ")";
    throw std::invalid_argument(message.str());
  }
  for (Eigen::Index i = 0; i < value.size(); ++i) {
    if (!std::isfinite(value[i])) {
      std::ostringstream message;
      message << name << '[' << i << "] is " << value[i] << ": every entry must be finite";
      throw std::invalid_argument(message.str());
    }
  }
}

}  // namespace iceskate_native
