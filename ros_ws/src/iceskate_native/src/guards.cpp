#include "iceskate_native/guards.hpp"

#include <cmath>
#include <stdexcept>

namespace iceskate_native
{

Guard guard_named(const std::string & name)
{
  for (std::size_t k = 0; k < kGuardNames.size(); ++k) {
    if (name == kGuardNames[k]) {
      return static_cast<Guard>(k);
    }
  }
  throw std::invalid_argument("unknown guard '" + name + "' (E1-E6, S1-S7)");
}

double guard_value(
  Guard guard, const Contact & contact, const Vector18 & q, const Vector18 & v,
  const DynamicsResult & r, const Friction & friction, const GuardConstants & c)
{
  switch (guard) {
    case Guard::kE1:  // support CoP reached the toe edge
      return r.support_wrench[3] - (c.sole_toe_y + c.cop_band) * r.support_normal;
    case Guard::kE2:  // support CoP reached the heel edge
      return (c.sole_heel_y - c.cop_band) * r.support_normal - r.support_wrench[3];
    case Guard::kE3:  // support sole came back flat
      return contact.pivot == 0 ? q[kQ1] : -q[kQ1];
    case Guard::kE4:  // holding the support foot needs more than friction: it starts gliding
      return (friction.ice ? -r.support_friction : std::abs(r.support_friction))
             - friction.mu * r.support_normal - c.force_band;
    case Guard::kE5:  // support glide stopped
      return -contact.support_slide_dir * v[kY0];
    case Guard::kE6:  // support normal force reached zero
      return -r.support_normal - c.force_band;
    case Guard::kS1:  // swing heel struck the floor
      return -r.swing_heel[2];
    case Guard::kS2:  // swing heel stopped sliding
      return -contact.heel_slide_dir * r.swing_heel_velocity[1];
    case Guard::kS3:  // pinning the swing heel needs more than friction: it starts sliding
      return (friction.ice ? -r.multipliers[1] : std::abs(r.multipliers[1]))
             - friction.mu * r.multipliers[0] - c.force_band;
    case Guard::kS4: {  // swing sole came flat
      double pitch = 0.0;
      for (int i = 1; i <= 7; ++i) {
        pitch += q[i];
      }
      return -pitch;
    }
    case Guard::kS5:  // swing sole un-flattens (toe lifts)
      return -r.multipliers[2] - c.moment_band;
    case Guard::kS6:  // swing contact force reached zero
      return -r.multipliers[0] - c.force_band;
    case Guard::kS7:  // swing toe reached the floor first
      return -r.swing_toe_z - c.toe_scuff;
  }
  throw std::invalid_argument("unknown guard");
}

}  // namespace iceskate_native
