// The gait modes of the paper's Table 2 as data (docs/model.md §3): which coordinates are
// active and which swing-foot constraints act. The table is Python's (iceskate_sim.model.modes); the
// native core receives it when a kernel is made and keeps no copy of its own, nor its size.
#pragma once

#include <array>
#include <vector>

#include "iceskate_native/coordinates.hpp"

namespace iceskate_native
{

/// A swing-foot constraint: heel height (hz), heel forward position (hy), flat sole (fr).
enum class Constraint
{
  kHeelZ,
  kHeelY,
  kSoleFlat
};

/// One row of Table 2.
struct Mode
{
  int number = 0;              ///< 1..the table's size
  bool y0_active = false;      ///< the support foot glides
  bool q1_active = false;      ///< the support foot tips about an edge
  bool swing_sliding = false;  ///< Coulomb friction on the swing heel
  std::vector<int> active;     ///< indices of the active coordinates, increasing
  std::vector<Constraint> constraints;  ///< in the order hz, hy, fr

  /// Index of a constraint's multiplier in the solution (-1: not active).
  int multiplier_index(Constraint c) const;
};

/// Zero the columns of `matrix` (18 columns; a Vector18's transpose() for its entries) of the
/// coordinates y0 and q1 where `mode` locks them.
template <class Matrix>
void zero_locked_columns(const Mode & mode, Matrix && matrix)
{
  if (!mode.y0_active) {
    matrix.col(kY0).setZero();
  }
  if (!mode.q1_active) {
    matrix.col(kQ1).setZero();
  }
}

/// The modes, indexed by number - 1.
using ModeTable = std::vector<Mode>;

/// Check a table (not empty, numbers 1..n in order, active indices in range and increasing,
/// constraint order hz, hy, fr, hz first); throws std::invalid_argument naming the first
/// problem.
void check_modes(const ModeTable & modes);

/// The mode `number` of `modes`; std::invalid_argument for a number the table does not hold.
const Mode & mode_numbered(const ModeTable & modes, int number);

}  // namespace iceskate_native
