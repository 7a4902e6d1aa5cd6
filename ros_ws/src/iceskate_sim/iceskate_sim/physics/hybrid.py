"""The discrete side of the hybrid gait automaton: ``HybridState``, the floor's
``FrictionModel``, the guard table ``GUARDS`` the native simulator receives, ``Transition`` and
the reasons a run ends. See docs/model.md §6-§7 and docs/architecture.md, 'The native core and
its test oracle'.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from iceskate_native.parameters import checked, setting
from iceskate_sim.errors import InputRefused
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import MODES, GaitMode
from iceskate_sim.model.robot import Q1, Y0

# Dead bands (hysteresis) of the force-based guards. A guard that is the complement of the
# transition just made (flat <-> edge, stick <-> slip, flat sole <-> heel only) would otherwise
# re-fire on round-off and chatter; these bands make each switch need a finite excess.
COP_BAND = 1.0e-3  # m: the support CoP must pass a sole edge by 1 mm (E1, E2)
FORCE_BAND = 0.5  # N: friction excess (E4, S3) and contact force below zero (E6, S6)
MOMENT_BAND = 0.05  # N m: swing-sole moment below zero before the sole un-flattens (S5)
# The model has no swing-toe contact: a toe dipping at most this far below the floor while the
# foot lifts or swings is a scuff, not a toe-first touchdown (S7).
TOE_SCUFF = 2.0e-3  # m


@dataclass(frozen=True)
class FrictionModel:
    """Floor friction (a scene's ``floor``)."""

    mu: float = setting(0.005, 'Coulomb coefficient (ice: 0.005 for forward sliding)', low=0.0,
                        high=2.0)
    rule: str = setting('ice', "'ice' (forward sliding only, a foot sliding back is stuck by "
                        "the toe pick) or 'coulomb' (|F_t| <= mu N both ways)",
                        choices=('ice', 'coulomb'))
    __post_init__ = checked(InputRefused)


@dataclass(frozen=True)
class HybridState:
    """Continuous and discrete state of the simulation.

    :param t: time [s]. :param q: coordinates (18,). :param v: velocities (18,).
    :param contact: mode, side, pivot, anchors and slide directions.
    :param step_index: number of support exchanges so far.
    :param t_exchange: time of the last support exchange t_e [s].
    :param t_touchdown: time of the last swing heel strike in this step [s] (nan: none yet).
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    contact: ContactState
    step_index: int = 0
    t_exchange: float = 0.0
    t_touchdown: float = float('nan')

    @property
    def mode(self) -> GaitMode:
        """The Table 2 mode."""
        return self.contact.mode

    def summary(self) -> str:
        """A one-line description for error messages."""
        return (f't={self.t:.6f} s, mode {self.mode.number} ({self.mode.support}/'
                f'{self.mode.swing}), support {self.contact.side} ({self.contact.pivot} pivot), '
                f'step {self.step_index}, y0={self.q[Y0]:.4f} m, q1={self.q[Q1]:.4f} rad, '
                f'|q|max={np.max(np.abs(self.q[1:])):.3g}, |v|max={np.max(np.abs(self.v)):.3g}')


@dataclass(frozen=True)
class Guard:
    """A transition guard: its name (E1-E6, S1-S7), the cause the event log gives, and the
    modes it applies in."""

    name: str
    cause: str
    applies: Callable[[GaitMode], bool]


GUARDS: tuple[Guard, ...] = (
    Guard('E1', 'support CoP reached the toe edge', lambda m: not m.q1_active),
    Guard('E2', 'support CoP reached the heel edge', lambda m: not m.q1_active),
    Guard('E3', 'support sole came back flat', lambda m: m.q1_active),
    Guard('E4', 'support friction limit exceeded: starts gliding', lambda m: not m.y0_active),
    Guard('E5', 'support glide stopped', lambda m: m.y0_active),
    Guard('E6', 'support normal force reached zero', lambda m: True),
    Guard('S1', 'swing heel struck the floor', lambda m: m.swing == 'A'),
    Guard('S7', 'swing toe reached the floor first', lambda m: m.swing == 'A'),
    Guard('S2', 'swing heel stopped sliding', lambda m: m.swing in ('Hs', 'Fs')),
    Guard('S3', 'swing heel friction limit exceeded: starts sliding',
          lambda m: m.swing in ('Hp', 'Fp')),
    Guard('S4', 'swing sole came flat', lambda m: m.swing in ('Hs', 'Hp')),
    Guard('S5', 'swing sole un-flattens (toe lifts)', lambda m: m.swing in ('Fs', 'Fp')),
    Guard('S6', 'swing contact force reached zero', lambda m: m.swing != 'A'),
)
_GUARDS_OF_MODE = {n: tuple(g for g in GUARDS if g.applies(m)) for n, m in MODES.items()}
#: The event log's cause of each guard's transition, by guard name.
CAUSES = {guard.name: guard.cause for guard in GUARDS}
#: The event log's cause of an 'R' entry, before the guard whose switches it ended.
RESOLVED = 'contact-consistent mode after a cycle of single switches'


def guards_of(mode: GaitMode) -> tuple[Guard, ...]:
    """The guards that apply in ``mode``, in the order the kernel evaluates them."""
    return _GUARDS_OF_MODE[mode.number]


@dataclass(frozen=True)
class Transition:
    """One entry of the event log (the empirical Fig. 3)."""

    t: float
    from_mode: int
    to_mode: int
    event: str
    cause: str
    impulse: tuple[float, ...] = ()
    step_index: int = 0
    side: str = 'right'


#: Why a run ends physically (``Simulator.ended``), for the ends the transitions detect.
FLIGHT = ("flight: the support foot left the floor with the swing foot in the air (not "
          "representable in the paper's model)")
TOE_FIRST = "toe-first touchdown of the swing foot (not representable in the paper's model)"


def fall_reason(fall_height: float) -> str:
    """Why a run ends when the head top falls below ``fall_height`` [m]."""
    return f'fall: head top below {fall_height} m'


def resolved_cause(guard: str) -> str:
    """The event log's cause of an 'R' entry: the cycle of ``guard``'s switches it ended."""
    return f'{RESOLVED} ({guard})'
