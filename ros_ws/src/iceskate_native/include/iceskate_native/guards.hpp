// The transition guards of the hybrid automaton (docs/model.md §6): a guard's value is positive
// when its transition is due. Which guards apply in which mode is data from Python
// (iceskate_sim.physics.hybrid.guards_of); their value formulas are here, by name, tested
// against the test oracle's (tests/oracle/automaton.py, GUARD_VALUES).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "iceskate_native/dynamics.hpp"

namespace iceskate_native
{

/// The guards by the names of the event log (E: support foot, S: swing foot).
enum class Guard
{
  kE1, kE2, kE3, kE4, kE5, kE6, kS1, kS2, kS3, kS4, kS5, kS6, kS7
};

/// The guards' names in the event log, in Guard's order.
constexpr std::array<const char *, 13> kGuardNames = {
  "E1", "E2", "E3", "E4", "E5", "E6", "S1", "S2", "S3", "S4", "S5", "S6", "S7"};

/// The guard called `name` ("E1".."E6", "S1".."S7"); std::invalid_argument otherwise.
Guard guard_named(const std::string & name);

/// Dead bands and geometry the guards use (iceskate_sim.physics.hybrid, iceskate_sim.model.robot).
struct GuardConstants
{
  double cop_band;     ///< [m] the support CoP passes a sole edge by this much (E1, E2)
  double force_band;   ///< [N] friction excess and contact force below zero (E4, E6, S3, S6)
  double moment_band;  ///< [N m] swing-sole moment below zero (S5)
  double toe_scuff;    ///< [m] a swing toe this far below the floor is a scuff (S7)
  double sole_toe_y;   ///< [m] toe edge relative to the ankle
  double sole_heel_y;  ///< [m] heel edge relative to the ankle
};

/// Floor friction: Coulomb coefficient and the rule (ice: a one-way clutch).
struct Friction
{
  double mu{};    ///< Coulomb coefficient (the scene's floor.mu)
  bool ice{};     ///< a one-way clutch: a foot sliding back sticks
};

/// The value of `guard` at the state (q, v) of `contact` with its dynamics `result`.
double guard_value(
  Guard guard, const Contact & contact, const Vector18 & q, const Vector18 & v,
  const DynamicsResult & result, const Friction & friction, const GuardConstants & constants);

/// The guards of every mode (index number - 1), in the order of Python's guards_of.
using GuardTable = std::vector<std::vector<Guard>>;

}  // namespace iceskate_native
