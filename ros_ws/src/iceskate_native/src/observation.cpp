#include "iceskate_native/observation.hpp"

#include <cmath>

namespace iceskate_native
{

std::int64_t stamp_ns(double t) { return static_cast<std::int64_t>(std::nearbyint(t * 1e9)); }

double stamp_time(double t) { return static_cast<double>(stamp_ns(t)) / 1e9; }

Observation observation_of(const HybridState & s, const Mode & mode)
{
  return {stamp_time(s.t), s.q, s.v, s.contact.mode, s.contact.side,
          mode.q1_active ? s.contact.pivot : 0, s.step_index, stamp_time(s.t_exchange),
          s.contact.heel_anchor_y,
          std::isfinite(s.t_touchdown) ? stamp_time(s.t_touchdown) : s.t_touchdown};
}

}  // namespace iceskate_native
