#!/usr/bin/env python3
"""Numerical-stability stress cases of the hybrid simulator.

Every case either behaves (the state stays finite, the constraint residual within the
simulator's bound) or stops cleanly: ``SimulationError`` with a reason, or ``Simulator.ended``
with a reason (fall, flight, toe-first touchdown). Never NaN propagation, never a hang: every
loop is bounded by its number of control periods, and every case runs under a wall-clock alarm
(SIGALRM) that turns a hang into a failed outcome. Cases:

* ``kp_x10`` / ``kp_x100``: the ``stand`` scene with the visual-lifting K_p times 10 / 100;
* ``step_tiny``: ``stand`` with implicit Euler at h = 1 us (1000 steps per control period);
* ``step_large_implicit``: ``stand`` with control period = implicit-Euler step = 20 ms;
* ``step_large_rk4`` / ``step_large_symplectic``: explicit methods at h = 1 ms, beyond their
  stability limit on the stiff damped links (~0.2 ms);
* ``straight_single``: single support (mode 1) with straight knees (upright posture);
* ``straight_double``: double support (mode 17) with all-straight legs: singular swing
  constraints, must be refused with a reason;
* ``near_straight_double``: double support with knees bent 1 mrad (near-singular);
* ``fast_arms`` / ``fast_legs``: ``stand`` started with 20 rad/s on the arms / 5 rad/s on the leg
  joints (the latter violates the closed-chain velocity constraints at t = 0);
* ``stiff_damping`` / ``stiff_damping_explicit``: the posture stabiliser's damping at 1e4
  N m s/rad (x125), implicit Euler / symplectic Euler at 0.1 ms;
* ``repeated_impacts``: single support, the swing foot held toe-up by a joint PD (plus gravity
  compensation) and dropped on its heel and lifted again every 0.6 s.

Each case runs period by period (``Simulator.advance``), so that every control instant's state
is checked. Figures per case: outcome, simulated time, wall time, transitions (heel strikes),
energy at the start and the end and its largest excursion, largest constraint residual.
``--long`` adds ``stand`` for ``--long-duration`` s (default 600) of simulated time in the native
blocks of periods the headless runner runs, with the head error, the constraint residual, the
energy and the process memory (RSS; with ``--tracemalloc`` also the traced Python allocations)
sampled every ``--window`` s, and says how long it ran.

Usage (from the repository root, environment sourced):
    python benchmarks/stress.py [--cases a,b] [--long] [--long-duration 600] [--json out.json]
"""

from __future__ import annotations

import argparse
import contextlib
import copy
from dataclasses import asdict, dataclass, field, replace
import importlib.util
import json
import pathlib
import resource
import signal
import sys
import time
import tracemalloc
from typing import Any, Callable

import numpy as np

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
for _package in ('iceskate_sim', 'visual_lifting', 'gait_manager'):
    if importlib.util.find_spec(_package) is None:  # workspace not sourced: use the sources
        sys.path.insert(0, str(REPO_ROOT / 'ros_ws' / 'src' / _package))
sys.path.append(str(REPO_ROOT / 'tests'))  # the Python oracle's commands

from iceskate_bringup.composition import ControlStack  # noqa: E402
from iceskate_bringup.runner import BLOCK_PERIODS  # noqa: E402
from iceskate_bringup.scene import load_scene, parse_scene  # noqa: E402
from iceskate_sim.errors import SimulationError  # noqa: E402
from iceskate_sim.model.command import HeldCommand  # noqa: E402
from iceskate_sim.model.robot import N_COORDINATES, load_robot  # noqa: E402
from iceskate_sim.physics.hybrid import FrictionModel  # noqa: E402
from iceskate_sim.physics.integrators import IntegratorConfig  # noqa: E402
from iceskate_sim.physics.simulation import Simulator, SimulatorConfig, initial_state  # noqa: E402
from iceskate_sim.run.scene import Scene  # noqa: E402
from oracle.commands import JointCommand, held_of, held_of_controllers, stack_commands  # noqa: E402

OUTCOMES = ('completed', 'ended', 'error', 'nan', 'hang', 'crash')
GOOD = ('completed', 'ended', 'error')
# A run that was not stopped with SimulationError but went past these has diverged without
# the simulator noticing (the robot's whole potential energy is ~1e3 J).
PLAUSIBLE_ENERGY = 1.0e4  # J, largest |E(t) - E(0)|
PLAUSIBLE_SPEED = 1.0e3  # rad/s or m/s, largest |v|
# Long stand run, from the first window starting after SETTLED_AFTER (the push at 2 s has
# died out) to the last: what counts as flat.
SETTLED_AFTER = 10.0  # s
FLAT_RSS_MB = 10.0  # resident memory growth
FLAT_ENERGY_J = 1.0e-3  # change of the total energy of a robot standing still


class Hang(Exception):
    """The wall-clock alarm of a case went off."""


@contextlib.contextmanager
def alarm(seconds: float):
    """Raise ``Hang`` in the main thread after ``seconds`` of wall time (SIGALRM).

    An alarm already armed (e.g. pytest-timeout's) is put back on exit with its remaining
    time, and fires first if it is due first.
    """
    def ring(signum, frame):
        raise Hang(f'no progress within {seconds:g} s of wall time')
    previous = signal.signal(signal.SIGALRM, ring)
    outer_delay, outer_interval = signal.getitimer(signal.ITIMER_REAL)
    signal.setitimer(signal.ITIMER_REAL, min(seconds, outer_delay) if outer_delay else seconds)
    start = time.monotonic()
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
        if outer_delay:
            remaining = max(outer_delay - (time.monotonic() - start), 1e-3)
            signal.setitimer(signal.ITIMER_REAL, remaining, outer_interval)


# --------------------------------------------------------------------------- outcome
@dataclass
class Outcome:
    """What a stress case did."""

    name: str
    outcome: str  # one of OUTCOMES
    reason: str | None
    sim_time: float
    wall: float
    periods: int
    transitions: int
    events: dict[str, int]
    energy_start: float
    energy_end: float
    energy_excursion: float  # max |E(t) - E(0)| over the control instants [J]
    max_residual: float  # largest constraint residual seen [m, rad]
    residual_bound: float
    finite: bool  # every sampled state finite
    max_speed: float = 0.0  # largest |v| at the control instants
    notes: list[str] = field(default_factory=list)

    @property
    def behaved(self) -> bool:
        """The contract: finite, residual bounded, and a clean outcome."""
        return (self.outcome in GOOD and self.finite
                and self.max_residual <= self.residual_bound)

    @property
    def plausible(self) -> bool:
        """False when the state ran away (energy or speed) without a SimulationError: the
        divergence was not detected (and was reported, if at all, as a physical end)."""
        if self.outcome == 'error':
            return True
        return not (self.energy_excursion > PLAUSIBLE_ENERGY or self.max_speed > PLAUSIBLE_SPEED)

    def line(self) -> str:
        """One line for the console."""
        events = ' '.join(f'{k}x{v}' for k, v in sorted(self.events.items())) or '-'
        reason = f'  ({self.reason[:110]})' if self.reason else ''
        flag = 'ok ' if self.behaved else 'BAD'
        if self.behaved and not self.plausible:
            flag = 'RAN'  # ran away undetected
        return (f'{self.name:24s} {self.outcome:9s} {flag} '
                f'{self.sim_time:7.3f} s sim {self.wall:7.2f} s wall  '
                f'dE {self.energy_end - self.energy_start:+10.3g} J '
                f'|dE|max {self.energy_excursion:9.3g} J  residual {self.max_residual:8.2e}  '
                f'events {events}{reason}')


# ----------------------------------------------------------------------------- cases
Controller = Callable[[Simulator], HeldCommand]


@dataclass(frozen=True)
class StressCase:
    """A case: how to build the simulator and its controller, and for how long to run."""

    name: str
    build: Callable[[Any], tuple[Simulator, Controller, Any]]  # robot -> (sim, ctrl, scene)
    duration: float  # s, test-suite length
    long_duration: float  # s, stress-command length
    expect: tuple[str, ...] = GOOD  # acceptable outcomes
    reason_contains: str | None = None  # required in the reason (error / ended)
    min_events: dict[str, int] = field(default_factory=dict)  # when it completed
    description: str = ''


def _scene_variant(name: str, edit: Callable[[dict], None]) -> Scene:
    raw = copy.deepcopy(load_scene(name).raw)
    edit(raw)
    raw.setdefault('record', {})['bag'] = False
    return parse_scene(raw)


def scene_case(edit: Callable[[dict], None], base: str = 'stand',
               initial_v: dict[int, float] | None = None,
               ) -> Callable[[Any], tuple[Simulator, Controller, Scene]]:
    """A builder running a variant of a shipped scene with the scene's controllers."""
    def build(robot: Any) -> tuple[Simulator, Controller, Scene]:
        scene = _scene_variant(base, edit)
        initial = scene.initial
        if initial_v:
            v = initial.v.copy()
            for i, value in initial_v.items():
                v[i] = value
            initial = replace(initial, v=v)
        sim = Simulator(robot, scene.simulator, initial)
        stack = ControlStack(scene, robot, sim.observation())

        def control(s: Simulator) -> HeldCommand:
            return held_of_controllers(stack_commands(stack, s.observation()).values())
        return sim, control, scene
    return build


def _kp(factor: float) -> Callable[[dict], None]:
    def edit(raw: dict) -> None:
        vl = raw['inputs'].setdefault('visual_lifting', {}) or {}
        vl['kp'] = [factor * k for k in (20.0, 290.0, 1100.0)]
        raw['inputs']['visual_lifting'] = vl
    return edit


def _integrator(method: str, step: float, period: float | None = None,
                ) -> Callable[[dict], None]:
    def edit(raw: dict) -> None:
        raw['integrator'] = {**raw.get('integrator', {}), 'method': method, 'step': step}
        if period is not None:
            raw['control_period'] = period
    return edit


def _posture(kind: str, knee_bend: float | None = None, mode: int | None = None,
             ) -> Callable[[dict], None]:
    def edit(raw: dict) -> None:
        raw['initial'] = {**raw.get('initial', {}), 'posture': kind}
        if knee_bend is not None:
            raw['initial']['knee_bend'] = knee_bend
        if mode is not None:
            raw['initial']['mode'] = mode
    return edit


def _stiff_damping(method: str | None = None, step: float | None = None,
                   ) -> Callable[[dict], None]:
    def edit(raw: dict) -> None:
        raw['inputs']['gait_manager']['posture']['damping'] = 1.0e4
        if method is not None:
            _integrator(method, step)(raw)
    return edit


def _nothing(raw: dict) -> None:
    del raw


def repeated_impacts(robot: Any) -> tuple[Simulator, Controller, None]:
    """Single support; the swing foot, toe up, is dropped on its heel and lifted every 0.6 s.

    A joint PD (600 N m/rad, 40 N m s/rad) on joints 2..17 plus gravity compensation tracks the
    bent stance with the swing leg shortened by ``lift`` (hip +lift, knee -2 lift, ankle +lift,
    plus a toe-up ankle offset): lift 0.06 rad holds the foot up, -0.02 rad pushes it into
    the floor.
    """
    a, toe_up = 0.05, 0.1

    def posture(lift: float) -> np.ndarray:
        q = np.zeros(N_COORDINATES)
        q[2:8] = (-a, 2 * a, -a, a + lift, -2 * a - 2 * lift, a + lift + toe_up)
        return q

    cfg = SimulatorConfig(control_period=1e-3, integrator=IntegratorConfig('implicit_euler',
                                                                           1e-3),
                          friction=FrictionModel(0.8, 'coulomb'))
    sim = Simulator(robot, cfg, initial_state(posture(0.06), 1, 'right', 'toe'))
    stiffness = np.zeros(N_COORDINATES)
    stiffness[2:] = 600.0
    damping = np.zeros(N_COORDINATES)
    damping[2:] = 40.0

    def control(s: Simulator) -> HeldCommand:
        lowered = (s.state.t % 0.6) >= 0.3
        gravity = np.zeros(N_COORDINATES)
        gravity[s.state.mode.active] = s.dynamics.gravity_terms(s.state.contact, s.state.q)
        gravity[:2] = 0.0
        return held_of([JointCommand(gravity, stiffness, damping,
                                                 posture(-0.02 if lowered else 0.06))])
    return sim, control, None


CASES: tuple[StressCase, ...] = (
    StressCase('kp_x10', scene_case(_kp(10.0)), 0.5, 3.0,
               description='stand, visual-lifting K_p x10'),
    StressCase('kp_x100', scene_case(_kp(100.0)), 0.5, 3.0,
               description='stand, visual-lifting K_p x100'),
    StressCase('step_tiny', scene_case(_integrator('implicit_euler', 1e-6)), 0.004, 0.02,
               description='stand, implicit Euler h = 1 us'),
    StressCase('step_large_implicit', scene_case(_integrator('implicit_euler', 0.02, 0.02)),
               1.0, 5.0, description='stand, control period = step = 20 ms'),
    StressCase('step_large_rk4', scene_case(_integrator('rk4', 1e-3)), 0.3, 1.0,
               description='stand, rk4 h = 1 ms (beyond its stability limit)'),
    StressCase('step_large_symplectic', scene_case(_integrator('symplectic_euler', 1e-3)), 0.3,
               1.0, description='stand, symplectic Euler h = 1 ms (beyond its stability limit)'),
    StressCase('straight_single', scene_case(_posture('upright', mode=1)), 0.5, 3.0,
               description='single support (mode 1), straight knees'),
    StressCase('straight_double', scene_case(_posture('upright')), 0.1, 0.1, expect=('error',),
               reason_contains='rank-deficient',
               description='double support (mode 17), all-straight legs: singular'),
    StressCase('near_straight_double', scene_case(_posture('bent_knees', knee_bend=1e-3)), 0.5,
               3.0, description='double support, knees bent 1 mrad (near-singular)'),
    StressCase('fast_arms', scene_case(_nothing, initial_v={i: 20.0 for i in range(11, 17)}),
               0.5, 3.0, description='stand, 20 rad/s on q11..q16 at t = 0'),
    StressCase('fast_legs', scene_case(_nothing, initial_v={i: 5.0 for i in range(2, 8)}),
               0.5, 3.0, description='stand, 5 rad/s on q2..q7 at t = 0 (violates the chain)'),
    StressCase('stiff_damping', scene_case(_stiff_damping()), 0.5, 3.0,
               description='stand, posture damping 1e4 N m s/rad, implicit Euler 1 ms'),
    StressCase('stiff_damping_explicit', scene_case(_stiff_damping('symplectic_euler', 1e-4)),
               0.1, 0.5, description='stand, posture damping 1e4, symplectic Euler 0.1 ms'),
    StressCase('repeated_impacts', repeated_impacts, 1.0, 6.0, min_events={'S1': 2},
               description='heel dropped and lifted every 0.6 s (single support)'),
)
FAST = tuple(c.name for c in CASES)  # every case has a short test-suite length


def case_by_name(name: str) -> StressCase:
    """The case called ``name``."""
    for case in CASES:
        if case.name == name:
            return case
    raise KeyError(f'unknown stress case {name!r}; one of {[c.name for c in CASES]}')


def _energy(sim: Simulator) -> float:
    kinetic, potential = sim.dynamics.energy(sim.state.contact, sim.state.q, sim.state.v)
    return kinetic + potential


def run_case(case: StressCase, duration: float, robot: Any = None,
             wall_limit: float = 60.0) -> Outcome:
    """Build and run one case for ``duration`` s of simulated time (bounded loop, alarm)."""
    robot = robot if robot is not None else load_robot()
    start = time.perf_counter()
    sim = None
    energies: list[float] = []
    finite = True
    outcome, reason = 'completed', None
    periods = 0
    max_speed = 0.0
    try:
        with alarm(wall_limit):
            sim, control, _ = case.build(robot)
            if sim.ended is not None:  # an initial state that ends the run at once
                outcome, reason = 'ended', f'at construction: {sim.ended}'
            if sim is not None:
                energies.append(_energy(sim))
                max_speed = float(np.max(np.abs(sim.state.v)))
                n_periods = int(round(duration / sim.config.control_period))
                for _ in range(max(n_periods, 1) if outcome == 'completed' else 0):
                    sim.advance(control(sim))
                    periods += 1
                    ok = bool(np.all(np.isfinite(sim.state.q)) and np.all(np.isfinite(
                        sim.state.v)))
                    finite = finite and ok
                    if not ok:
                        outcome, reason = 'nan', f'non-finite state at t={sim.state.t:.6f} s'
                        break
                    energies.append(_energy(sim))
                    max_speed = max(max_speed, float(np.max(np.abs(sim.state.v))))
                    if sim.ended is not None:
                        outcome, reason = 'ended', sim.ended
                        break
    except SimulationError as exc:
        outcome, reason = 'error', str(exc).splitlines()[0]
    except Hang as exc:
        outcome, reason = 'hang', str(exc)
    except Exception as exc:  # noqa: BLE001 - any other exception breaks the contract
        outcome, reason = 'crash', f'{type(exc).__name__}: {exc}'
    wall = time.perf_counter() - start
    energies_arr = np.array(energies) if energies else np.array([np.nan])
    if not np.all(np.isfinite(energies_arr)) and outcome in GOOD and energies:
        finite = False
    events: dict[str, int] = {}
    if sim is not None:
        for e in sim.events:
            events[e.event] = events.get(e.event, 0) + 1
    return Outcome(
        case.name, outcome, reason, float(sim.state.t) if sim is not None else 0.0, wall,
        periods, len(sim.events) if sim is not None else 0, events,
        float(energies_arr[0]), float(energies_arr[-1]),
        float(np.nanmax(np.abs(energies_arr - energies_arr[0]))) if energies else float('nan'),
        float(sim.stats.max_constraint_residual) if sim is not None else 0.0,
        sim.config.residual_bound if sim is not None else float('inf'), finite, max_speed)


def check(case: StressCase, result: Outcome) -> list[str]:
    """Problems of an outcome against the case's contract (empty: passed)."""
    problems = []
    if not result.behaved:
        problems.append(f'contract broken: outcome {result.outcome}, finite {result.finite}, '
                        f'residual {result.max_residual:.3g} (bound {result.residual_bound:g})')
    if result.outcome not in case.expect:
        problems.append(f'outcome {result.outcome!r} not among {case.expect}')
    if result.outcome in ('error', 'ended') and not result.reason:
        problems.append('stopped without a reason')
    if case.reason_contains and case.reason_contains not in (result.reason or ''):
        problems.append(f'reason lacks {case.reason_contains!r}: {result.reason}')
    if result.outcome == 'completed':
        for event, count in case.min_events.items():
            if result.events.get(event, 0) < count:
                problems.append(f'{event} x{result.events.get(event, 0)} < {count}')
    return problems


# ----------------------------------------------------------------------- long run
def _rss_mb() -> float:
    """Current resident set size [MB] (Linux /proc), else the peak from getrusage."""
    try:
        for line in pathlib.Path('/proc/self/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def long_stand(duration: float, window: float, robot: Any, wall_limit: float,
               log: Callable[[str], None], trace: bool = False) -> dict[str, Any]:
    """``stand`` for ``duration`` s in the native blocks of periods the headless runner runs
    (``BLOCK_PERIODS`` a call, nothing recorded): per-window drift and memory figures.

    The head error of a window is the largest distance (y, z) of the head top from the target
    visual lifting steers to, over the window's control instants; the constraint residual is
    the simulator's running maximum.

    :param trace: also trace Python allocations (tracemalloc; slows the run down).
    """
    scene = _scene_variant('stand', _nothing)
    sim = Simulator(robot, scene.simulator, scene.initial)
    stack = ControlStack(scene, robot, sim.observation())
    obs = sim.observation()
    loop = sim.control_loop(stack.kinematics, list(stack.controllers.values()), scene.pushes,
                            sim.dynamics.head_pose(obs.contact(), obs.q)[0])
    period = scene.simulator.control_period
    per_window = max(1, int(round(window / period)))
    n_periods = int(round(duration / period))
    if trace:
        tracemalloc.start()
    windows: list[dict[str, Any]] = []
    head_err = 0.0
    outcome, reason = 'completed', None
    start = time.perf_counter()
    done = 0
    try:
        with alarm(wall_limit):
            while done < n_periods:
                window_end = min(n_periods, (done // per_window + 1) * per_window)
                block, error = sim.run_loop(loop, min(BLOCK_PERIODS, window_end - done))
                done += len(block['t'])
                if len(block['t']):
                    if not (np.all(np.isfinite(block['q'])) and np.all(np.isfinite(block['v']))):
                        outcome = 'nan'
                        reason = f'non-finite state in the block before t={sim.state.t:.3f} s'
                        break
                    miss = block['head_position'][:, 1:] - block['head_target'][:, :2]
                    head_err = max(head_err, float(np.max(np.linalg.norm(miss, axis=1))))
                if error is not None:
                    raise error
                if not (np.all(np.isfinite(sim.state.q)) and np.all(np.isfinite(sim.state.v))):
                    outcome, reason = 'nan', f'non-finite state at t={sim.state.t:.3f} s'
                    break
                if sim.ended is not None:
                    outcome, reason = 'ended', sim.ended
                    break
                if done == window_end:
                    traced, traced_peak = tracemalloc.get_traced_memory()
                    psi = sim.dynamics.head_pose(sim.state.contact, sim.state.q)[0]
                    row = {'t': sim.state.t, 'wall_s': time.perf_counter() - start,
                           'head_err_max_m': head_err, 'energy_J': _energy(sim),
                           'residual_max': sim.stats.max_constraint_residual,
                           'head_y_m': float(psi[0]), 'head_z_m': float(psi[1]),
                           'q_drift_max': float(np.max(np.abs(sim.state.q
                                                              - scene.initial.q))),
                           'speed_max': float(np.max(np.abs(sim.state.v))),
                           'rss_mb': _rss_mb(), 'traced_mb': traced / 2**20,
                           'traced_peak_mb': traced_peak / 2**20}
                    windows.append(row)
                    log(f'  stand t={row["t"]:7.1f} s wall {row["wall_s"]:7.1f} s  head err '
                        f'{head_err:.2e} m  E {row["energy_J"]:.6f} J  residual '
                        f'{row["residual_max"]:.1e}  |q-q0|max {row["q_drift_max"]:.2e}  RSS '
                        f'{row["rss_mb"]:.1f} MB  traced {row["traced_mb"]:.2f} MB')
                    head_err = 0.0
    except SimulationError as exc:
        outcome, reason = 'error', str(exc).splitlines()[0]
    except Hang as exc:
        outcome, reason = 'hang', str(exc)
    finally:
        if trace:
            tracemalloc.stop()
    wall = time.perf_counter() - start
    summary = {'requested_s': duration, 'simulated_s': float(sim.state.t), 'wall_s': wall,
               'rtf': float(sim.state.t) / wall if wall > 0 else float('nan'),
               'outcome': outcome, 'reason': reason, 'windows': windows}
    settled = [w for w in windows if w['t'] - window >= SETTLED_AFTER - 1e-9]
    if len(settled) >= 2:
        first, last = settled[0], settled[-1]
        summary['drift'] = {
            'head_err_first_window_m': first['head_err_max_m'],
            'head_err_last_window_m': last['head_err_max_m'],
            'energy_change_J': last['energy_J'] - first['energy_J'],
            'residual_max': last['residual_max'],
            'rss_growth_mb': last['rss_mb'] - first['rss_mb'],
            'traced_growth_mb': last['traced_mb'] - first['traced_mb'],
            'from_t': first['t'], 'to_t': last['t']}
        d = summary['drift']
        summary['flat'] = {
            'memory': d['rss_growth_mb'] <= FLAT_RSS_MB,
            'energy': abs(d['energy_change_J']) <= FLAT_ENERGY_J,
            'head_error': d['head_err_last_window_m'] <= max(2.0 * d['head_err_first_window_m'],
                                                            1e-6),
            'residual': d['residual_max'] <= 1e-9}
    return summary


# ----------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    """Run the cases (and the long stand); print a table; exit 1 if a contract broke."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cases', help='comma-separated subset (default: all)')
    parser.add_argument('--short', action='store_true',
                        help='test-suite lengths instead of the stress lengths')
    parser.add_argument('--long', action='store_true', help='also run stand for a long time')
    parser.add_argument('--long-duration', type=float, default=600.0,
                        help='simulated seconds of the long stand run (default 600)')
    parser.add_argument('--window', type=float, default=30.0,
                        help='sampling window of the long run [s simulated]')
    parser.add_argument('--case-wall-limit', type=float, default=300.0,
                        help='alarm per case [s of wall time]')
    parser.add_argument('--tracemalloc', action='store_true',
                        help='long run: also trace Python allocations (slower)')
    parser.add_argument('--json', type=pathlib.Path, help='write the figures to this file')
    args = parser.parse_args(argv)
    started = time.perf_counter()

    def log(message: str) -> None:
        print(f'{time.perf_counter() - started:7.1f}s {message}', flush=True)

    names = args.cases.split(',') if args.cases else [c.name for c in CASES]
    try:
        cases = [case_by_name(n) for n in names]
    except KeyError as exc:
        parser.error(str(exc))
    robot = load_robot()
    results, failures = [], 0
    for case in cases:
        duration = case.duration if args.short else case.long_duration
        result = run_case(case, duration, robot, args.case_wall_limit)
        result.notes = check(case, result)
        failures += bool(result.notes)
        results.append(result)
        log(result.line())
        for note in result.notes:
            log(f'    FAIL {case.name}: {note}')
        if not result.plausible:
            log(f'    WARN {case.name}: ran away undetected (|dE|max '
                f'{result.energy_excursion:.3g} J, |v|max {result.max_speed:.3g}) and stopped as '
                f'{result.outcome!r}, not with SimulationError')
    figures: dict[str, Any] = {'cases': [asdict(r) | {'behaved': r.behaved,
                                                      'plausible': r.plausible}
                                         for r in results]}
    if args.long:
        log(f'long run: stand for {args.long_duration:g} s of simulated time '
            f'(window {args.window:g} s)')
        long = long_stand(args.long_duration, args.window, robot,
                          max(args.case_wall_limit, 20.0 * args.long_duration), log,
                          args.tracemalloc)
        figures['long_stand'] = long
        log(f'long run: {long["outcome"]}{" (" + long["reason"] + ")" if long["reason"] else ""}'
            f'; ran {long["simulated_s"]:.1f} s of simulated time (requested '
            f'{long["requested_s"]:g} s) in {long["wall_s"]:.1f} s of wall time '
            f'({long["rtf"]:.2f}x real time)')
        if 'drift' in long:
            d = long['drift']
            log(f'long run drift from t={d["from_t"]:.0f} s to t={d["to_t"]:.0f} s: head error '
                f'{d["head_err_first_window_m"]:.2e} -> {d["head_err_last_window_m"]:.2e} m, '
                f'energy {d["energy_change_J"]:+.3e} J, residual (largest of the run) '
                f'{d["residual_max"]:.1e}, RSS {d["rss_growth_mb"]:+.2f} MB, traced '
                f'Python memory {d["traced_growth_mb"]:+.3f} MB')
            flat = long['flat']
            log('long run flat: ' + ', '.join(f'{k} {"yes" if v else "NO"}'
                                              for k, v in flat.items())
                + f' (RSS growth <= {FLAT_RSS_MB:g} MB, |dE| <= {FLAT_ENERGY_J:g} J, head error '
                'at most 2x the first window, residual <= 1e-9)')
        if long['outcome'] not in GOOD:
            failures += 1
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=1, default=float) + '\n')
        log(f'figures written to {args.json}')
    runaway = [r.name for r in results if not r.plausible]
    log(f'{len(results)} cases, {failures} broke their contract; ran away undetected: '
        f'{runaway or "none"}; {time.perf_counter() - started:.0f} s in all')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
