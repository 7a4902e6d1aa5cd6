#!/usr/bin/env python3
"""Work-precision benchmark of the integrators: wall time against error.

For every integrator of the simulator (symplectic_euler, implicit_euler, rk4; the adaptive rk45
and ros34pw2) and a sweep of fixed steps or tolerances, one closed-loop run (the scene's
controllers at every control instant in the native blocks of periods, as ``run_scene`` does,
without recording) is timed and
compared with a reference run of the same case at the tightest setting: rk45 (Dormand-Prince
5(4)) at rtol 1e-12, atol 1e-2 rtol, or at the case's own tolerance where the kernel's step-size
control cannot hold 1e-12 over the whole run: it stops with "the step size fell below 1e-14 s"
on ``walk`` at 1e-12 (its reference is rtol 1e-11) and on ``skate`` at 1e-12, 1e-11 and 1e-10
within its 15 s (its reference is rtol 1e-9); a reference that fails anyway is run again 10x
looser, and the log and the outputs say so). That the reference has converged is measured,
not assumed: the same case at 10x its rtol is run too and its distance from the reference
printed (it must be well below the errors being compared). Cases:

* ``smooth``: the ``stand`` scene with the soft joint stops off, 0.4 s before the push: one mode
  (17), no events, visual lifting and the posture impedance running (a smooth right-hand side;
  with the stops on, the elbows rest on their stop at q = 0 and the kink of the stop force
  caps every fixed-step method at first order);
* ``events``: the ``walk`` scene as shipped, 1.28 s: its first step, with support-heel rocking
  (E2, E3), lift-off (S6), heel strike (S1, an impact), heel stop (S2) and sole flat (S4, an
  impact) (the events of the reference run are listed in the outputs);
* ``passive``: the bent-knee double support (mode 17) with no inputs, joint damping and stops
  off, 0.3 s: a conservative system, so the energy drift is the integrator's;
* ``skate``: the shipped ``skate`` scene, the whole 15 s (``--quick``: 2 s), with its events:
  the goal figure below (the shipped implicit Euler and the cheap accurate settings of rk4,
  rk45, ros34pw2).

Figures per run, against the reference interpolated onto the run's samples (one per control
period): ``head_err_max`` = max over the samples of |p_head - p_ref| (head-top y, z) [m];
``final_q_err`` / ``final_v_err`` = max abs difference of q / v at the last common sample;
``energy_drift`` = max |E(t) - E(0)| [J] (passive case); ``residual`` = the simulator's largest
constraint residual (measured before each end-of-period projection) [m, rad].

Outputs into ``--out`` (default runs/bench): ``work_precision_<case>.png`` (log-log error against
wall time, one line per method), ``work_precision.md`` (tables) and ``work_precision.json`` (raw
figures, machine). Then the headline: real-time factor of the headless ``stand`` and ``skate``
scenes at their shipped settings (``iceskate_bringup.runner.run``, no output), and the goal: the
cheapest setting of the skate case with head-trajectory error <= 1e-6 m, and its real-time
factor (goal >= 30x).

Usage (from the repository root, environment sourced):
    python benchmarks/bench_work_precision.py [--out runs/bench] [--quick] [--cases smooth,...]
"""

from __future__ import annotations

import argparse
import copy
from dataclasses import dataclass, field, replace
import importlib.util
import json
import os
import pathlib
import platform
import statistics
import sys
import time
from typing import Any

import numpy as np

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
REFERENCE = ('rk45', 1.0e-12)  # method, tightest rtol (atol = 1e-2 rtol)
REFERENCE_LOOSEST = 1.0e-8  # a reference that fails is tried again 10x looser, down to this
CHECK_FACTOR = 10.0  # the convergence check runs the reference's rtol times this
SKATE_REFERENCE_RTOL = 1.0e-9  # the tightest the native rk45 holds over the whole skate scene
WALK_REFERENCE_RTOL = 1.0e-11  # the same over walk's first step (1e-12 stops at t = 0.14 s)
GOAL_RTF = 30.0  # real-time factor of the cheapest setting within the head-error goal
GOAL_HEAD_ERROR = 1.0e-6  # m
ERROR_FLOOR = 1.0e-16  # plotted in place of an exact zero


def import_core() -> None:
    """Make iceskate_sim, visual_lifting and gait_manager importable from the source tree
    when the workspace is not sourced."""
    for package in ('iceskate_sim', 'visual_lifting', 'gait_manager'):
        if importlib.util.find_spec(package) is None:
            sys.path.insert(0, str(REPO_ROOT / 'ros_ws' / 'src' / package))


import_core()

from iceskate_bringup.composition import ControlStack  # noqa: E402
from iceskate_bringup.runner import BLOCK_PERIODS  # noqa: E402
from iceskate_bringup.scene import load_scene, parse_scene  # noqa: E402
from iceskate_sim.errors import SimulationError  # noqa: E402
from iceskate_sim.model.dynamics import ContactState  # noqa: E402
from iceskate_sim.model.modes import MODES  # noqa: E402
from iceskate_sim.model.robot import PIVOTS, SIDES, load_robot  # noqa: E402
from iceskate_sim.physics.integrators import FIXED_STEP as FIXED  # noqa: E402
from iceskate_sim.physics.integrators import METHODS, IntegratorConfig  # noqa: E402
from iceskate_sim.physics.simulation import Simulator  # noqa: E402
from iceskate_sim.run.scene import Scene  # noqa: E402


# ------------------------------------------------------------------------------ driver
@dataclass
class Run:
    """One timed closed-loop run: samples at every control instant (t_0 = start)."""

    label: str
    method: str
    step: float
    rtol: float
    wall: float  # s, control laws + simulation (samples are post-processed outside)
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    head: np.ndarray  # (N, 2) head-top y, z [m]
    energy: np.ndarray  # (N,) kinetic + potential [J]
    discrete: np.ndarray  # (N, 3) mode number, support side (0 right, 1 left), step index
    evaluations: int
    steps: int
    periods: int
    residual: float
    transitions: int
    events: list[str] = field(default_factory=list)
    ended: str | None = None
    error: str | None = None

    @property
    def sim_time(self) -> float:
        """Simulated time covered [s]."""
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0

    @property
    def status(self) -> str:
        """'ok', or why the run stopped early."""
        if self.error:
            return f'error: {self.error}'
        if self.ended:
            return f'ended: {self.ended}'
        return 'ok'


def integrator_config(method: str, setting: float, period: float) -> IntegratorConfig:
    """Fixed-step methods: ``setting`` is the step [s]; adaptive ones (rk45, ros34pw2): the rtol
    (atol = 1e-2 rtol, max step = the control period)."""
    if method in FIXED:
        return IntegratorConfig(method=method, step=setting)
    return IntegratorConfig(method=method, step=period, rtol=setting, atol=setting * 1e-2)


def simulate(scene: Scene, duration: float, integrator: IntegratorConfig | None = None,
             robot: Any = None, max_wall: float = float('inf'), label: str = '',
             energy: bool = False, stack_class: type = ControlStack,
             **config_changes: Any) -> Run:
    """Run ``scene`` for ``duration`` [s] the way ``run_scene`` does (same control stack,
    pushes, zero-order hold, the same native blocks of periods), without recording; stop after
    ``max_wall`` s of wall time.

    :param integrator: replaces the scene's integrator (None: keep it).
    :param stack_class: the controllers (``ControlStack`` or a variant with its signature).
    :param config_changes: other ``SimulatorConfig`` fields to replace (e.g. fall_height).
    """
    robot = robot if robot is not None else load_robot()
    cfg = scene.simulator
    if integrator is not None:
        cfg = replace(cfg, integrator=integrator)
    if config_changes:
        cfg = replace(cfg, **config_changes)
    sim = Simulator(robot, cfg, scene.initial)
    stack = stack_class(scene, robot, sim.observation())
    n_periods = int(round(duration / cfg.control_period))
    obs = sim.observation()
    loop = sim.control_loop(stack.kinematics, list(stack.controllers.values()), scene.pushes,
                            sim.dynamics.head_pose(obs.contact(), obs.q)[0])
    start = time.perf_counter()
    blocks, error = _native_blocks(sim, loop, n_periods, start, max_wall)
    wall = time.perf_counter() - start
    # the state each period started from (after the transitions due then), then the last
    samples = [(t, q, v, ContactState(MODES[mode], SIDES[side], PIVOTS[pivot]), step)
               for b in blocks for t, q, v, mode, side, pivot, step in zip(
                   b['t'], b['q'], b['v'], b['mode'].tolist(), b['side'].tolist(),
                   b['pivot'].tolist(), b['step_index'].tolist(), strict=True)]
    samples.append((sim.state.t, sim.state.q.copy(), sim.state.v.copy(), sim.state.contact,
                    sim.state.step_index))
    dyn = sim.dynamics
    head = np.array([dyn.frame_placement(c, q, 'head_top').translation[1:3]
                     for _, q, _, c, _ in samples])
    energies = (np.array([sum(dyn.energy(c, q, v)) for _, q, v, c, _ in samples]) if energy
                else np.full(len(samples), np.nan))
    integ = cfg.integrator
    discrete = np.array([(c.mode.number, c.side == 'left', step) for _, _, _, c, step
                         in samples], dtype=int)
    return Run(label, integ.method, integ.step, integ.rtol, wall,
               np.array([s[0] for s in samples]), np.array([s[1] for s in samples]),
               np.array([s[2] for s in samples]), head, energies, discrete,
               sim.stats.evaluations,
               sim.stats.steps, sim.stats.control_periods, sim.stats.max_constraint_residual,
               len(sim.events), [e.event for e in sim.events], sim.ended, error)


def _native_blocks(sim: Simulator, loop: Any, n_periods: int, start: float,
                   max_wall: float) -> tuple[list[dict[str, Any]], str | None]:
    """Blocks of ``BLOCK_PERIODS`` native periods until ``n_periods`` are done, the run ends,
    fails (its error, first line) or passes ``max_wall`` s of wall time since ``start``."""
    blocks = []
    while sim.stats.control_periods < n_periods and sim.ended is None:
        block, failure = sim.run_loop(loop, min(BLOCK_PERIODS,
                                                n_periods - sim.stats.control_periods))
        blocks.append(block)
        if failure is not None:
            return blocks, str(failure).splitlines()[0][:200]
        if time.perf_counter() - start > max_wall:
            return blocks, f'wall-time limit {max_wall:g} s reached at t={sim.state.t:.4f} s'
    return blocks, None


def compare(run: Run, ref: Run) -> dict[str, float]:
    """Errors of ``run`` against ``ref`` over their common time span (reference interpolated
    onto the run's samples)."""
    t_end = min(run.t[-1], ref.t[-1])
    keep = run.t <= t_end + 1e-12
    t = run.t[keep]

    def at(values: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, ref.t, values[:, k])
                                for k in range(values.shape[1])])
    head_err = np.linalg.norm(run.head[keep] - at(ref.head), axis=1)
    last = int(np.searchsorted(ref.t, t[-1] - 1e-12))
    out = {
        # q is support-rooted: after a support exchange at another instant, or in another
        # mode, final_q_err compares relabelled coordinates; this says whether it did not
        'final_discrete_match': bool(np.array_equal(run.discrete[keep][-1],
                                                    ref.discrete[min(last, len(ref.t) - 1)])),
        'head_err_max': float(np.max(head_err)),
        'final_q_err': float(np.max(np.abs(run.q[keep][-1] - at(ref.q)[-1]))),
        'final_v_err': float(np.max(np.abs(run.v[keep][-1] - at(ref.v)[-1]))),
        'compared_until_s': float(t[-1]),
    }
    if np.all(np.isfinite(run.energy)):
        out['energy_drift'] = float(np.max(np.abs(run.energy - run.energy[0])))
    return out


# ------------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class Case:
    """A benchmark case: a scene, a duration and the sweep per method."""

    name: str
    title: str
    scene: Scene
    duration: float
    sweep: dict[str, tuple[float, ...]]
    energy: bool = False
    reference_rtol: float = REFERENCE[1]


def _scene(name: str, **edits: Any) -> Scene:
    """A shipped scene with top-level keys replaced (None deletes the key)."""
    raw = copy.deepcopy(load_scene(name).raw)
    for key, value in edits.items():
        if value is None:
            raw.pop(key, None)
        else:
            raw[key] = value
    return parse_scene(raw)


def make_cases(quick: bool) -> list[Case]:
    """The cases and their sweeps (``quick``: shorter spans, fewer settings)."""
    stand_raw = load_scene('stand').raw
    smooth = _scene('stand', dynamics={**stand_raw.get('dynamics', {}), 'joint_limits': False},
                    disturbances=None)
    passive = _scene('stand', dynamics={'joint_limits': False, 'damping': False}, inputs={},
                     disturbances=None)
    walk = load_scene('walk')
    skate = load_scene('skate')
    if quick:
        return [
            Case('smooth', 'stand, soft stops off, mode 17, 0.1 s (no events)', smooth, 0.1, {
                'symplectic_euler': (5e-5, 2.5e-5), 'implicit_euler': (1e-3, 2.5e-4),
                'rk4': (1e-4, 5e-5), 'rk45': (1e-4, 1e-8), 'ros34pw2': (1e-3, 1e-6)}),
            Case('events', 'walk as shipped, 0.6 s (with events)', walk, 0.6, {
                'implicit_euler': (1e-3, 2.5e-4), 'rk4': (1e-4,), 'rk45': (1e-4,),
                'ros34pw2': (1e-2, 1e-4)}, reference_rtol=WALK_REFERENCE_RTOL),
            Case('passive', 'mode 17, no inputs, no damping/stops, 0.2 s', passive, 0.2, {
                'symplectic_euler': (1e-3, 2.5e-4), 'implicit_euler': (1e-3,),
                'rk4': (1e-3, 2.5e-4), 'rk45': (1e-6,), 'ros34pw2': (1e-4,)}, energy=True),
            Case('skate', 'skate as shipped, 2 s (with events)', skate, 2.0, {
                'implicit_euler': (1e-3,), 'rk4': (2e-4,), 'rk45': (1e-4,),
                'ros34pw2': (1e-2, 1e-4)}, reference_rtol=SKATE_REFERENCE_RTOL),
        ]
    return [
        Case('smooth', 'stand, soft stops off, mode 17, 0.4 s (no events)', smooth, 0.4, {
            'symplectic_euler': (1e-4, 5e-5, 2.5e-5, 1e-5),
            'implicit_euler': (1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5),
            'rk4': (1e-4, 5e-5, 2.5e-5),
            'rk45': (1e-3, 1e-5, 1e-7, 1e-9),
            'ros34pw2': (1e-3, 1e-5, 1e-7, 1e-9)}),
        Case('events', 'walk as shipped, 1.28 s (first step, with events)', walk, 1.28, {
                 'symplectic_euler': (5e-5, 2.5e-5),
                 'implicit_euler': (1e-3, 5e-4, 2.5e-4, 1e-4),
                 'rk4': (1e-4, 5e-5, 2.5e-5),
                 'rk45': (1e-4, 1e-6, 1e-8),
                 'ros34pw2': (1e-2, 1e-3, 1e-4, 1e-5)}, reference_rtol=WALK_REFERENCE_RTOL),
        Case('passive', 'mode 17, no inputs, joint damping and stops off, 0.3 s', passive, 0.3,
             {'symplectic_euler': (1e-3, 5e-4, 2.5e-4, 1e-4),
              'implicit_euler': (1e-3, 5e-4, 2.5e-4, 1e-4),
              'rk4': (1e-3, 5e-4, 2.5e-4),
              'rk45': (1e-4, 1e-6, 1e-8),
              'ros34pw2': (1e-3, 1e-5, 1e-7)}, energy=True),
        Case('skate', f'skate as shipped, the whole {skate.duration:g} s (with events)', skate,
             skate.duration,
             {'implicit_euler': (1e-3, 2.5e-4, 1e-4), 'rk4': (2e-4, 1e-4, 5e-5),
              'rk45': (1e-2, 1e-3, 1e-4, 1e-6),
              'ros34pw2': (1e-1, 3e-2, 1e-2, 1e-3, 1e-4, 1e-5)},
             reference_rtol=SKATE_REFERENCE_RTOL),
    ]


def run_case(case: Case, robot: Any, max_wall: float, log) -> dict[str, Any]:
    """Reference, its convergence check and the sweep of one case; returns its JSON figures."""
    period = case.scene.simulator.control_period
    ref_method, ref_rtol = REFERENCE[0], case.reference_rtol
    failed = []
    while True:
        ref = simulate(case.scene, case.duration,
                       integrator_config(ref_method, ref_rtol, period), robot, max_wall * 4,
                       'reference', case.energy)
        if ref.error is None or ref_rtol * 10.0 > REFERENCE_LOOSEST * (1 + 1e-9):
            break
        failed.append({'rtol': ref_rtol, 'error': ref.error})
        log(f'[{case.name}] reference {ref_method} rtol {ref_rtol:g} stopped ({ref.status[:90]}'
            f'); again at rtol {ref_rtol * 10.0:g}')
        ref_rtol *= 10.0
    log(f'[{case.name}] reference {ref_method} rtol {ref_rtol:g}: {ref.wall:.1f} s wall, '
        f'{ref.evaluations} evaluations, {ref.transitions} transitions '
        f'{" ".join(ref.events[:30])}{" ..." if len(ref.events) > 30 else ""}, {ref.status}')
    check_rtol = ref_rtol * CHECK_FACTOR
    check = simulate(case.scene, case.duration, integrator_config(ref_method, check_rtol,
                                                                    period),
                     robot, max_wall * 4, 'reference check', case.energy)
    converged = compare(check, ref)
    converged.update(rtol=check_rtol, wall_s=check.wall, status=check.status,
                     same_events=check.events == ref.events)
    log(f'[{case.name}] reference converged: {ref_method} rtol {check_rtol:g} against rtol '
        f'{ref_rtol:g}: head {converged["head_err_max"]:.2e} m, final q '
        f'{converged["final_q_err"]:.2e}, same events {converged["same_events"]} '
        f'({check.wall:.1f} s wall, {check.status})')
    rows = [_row(ref, ref, period)]
    for method in METHODS:
        for setting in case.sweep.get(method, ()):
            try:
                integ = integrator_config(method, setting, period)
            except SimulationError as exc:
                log(f'[{case.name}] {method} {setting:g}: skipped ({exc})')
                continue
            run = simulate(case.scene, case.duration, integ, robot, max_wall,
                           f'{method} {setting:g}', case.energy)
            row = _row(run, ref, period)
            rows.append(row)
            log(f'[{case.name}] {method:16s} {_setting(method, setting):>11s} '
                f'{run.wall:7.2f} s ({row["rtf"]:6.2f}x)  head {row["head_err_max"]:.2e} m'
                f'  final q {row["final_q_err"]:.2e}  residual {run.residual:.1e}  '
                f'{run.status}')
    return {'name': case.name, 'title': case.title, 'duration_s': case.duration,
            'reference': {'method': ref_method, 'rtol': ref_rtol, 'atol': ref_rtol * 1e-2,
                          'failed_tighter': failed},
            'reference_converged': converged,
            'events_in_reference': ref.events, 'runs': rows}


def _setting(method: str, setting: float) -> str:
    return f'h={setting:g}' if method in FIXED else f'rtol={setting:g}'


def _row(run: Run, ref: Run, period: float) -> dict[str, Any]:
    setting = run.step if run.method in FIXED else run.rtol
    row = {'method': run.method,
           'setting': _setting(run.method, setting),
           'step': run.step, 'rtol': run.rtol, 'reference': run is ref, 'wall_s': run.wall,
           'sim_time_s': run.sim_time,
           'rtf': run.sim_time / run.wall if run.wall > 0 else float('nan'),
           'evaluations': run.evaluations, 'physics_steps': run.steps,
           'evaluations_per_period': run.evaluations / max(run.periods, 1),
           'transitions': run.transitions, 'residual': run.residual, 'status': run.status}
    row.update(compare(run, ref))
    if not np.all(np.isfinite(run.energy)):
        row.pop('energy_drift', None)
    return row


# ---------------------------------------------------------------------------- outputs
def plot_case(case: dict[str, Any], path: pathlib.Path) -> None:
    """Log-log head error against wall time, one line per method."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    colours = {method: f'C{k}' for k, method in enumerate(METHODS)}
    for method in METHODS:
        rows = [r for r in case['runs'] if r['method'] == method and not r['reference']]
        if not rows:
            continue
        for ax, key in zip(axes, ('head_err_max', 'final_q_err'), strict=True):
            x = [r['wall_s'] for r in rows]
            y = [max(r[key], ERROR_FLOOR) for r in rows]
            line, = ax.loglog(x, y, 'o-', color=colours[method], label=method)
            for r, xi, yi in zip(rows, x, y, strict=True):
                marker = r['setting'].split('=')[1] + ('' if r['status'] == 'ok' else ' (!)')
                ax.annotate(marker, (xi, yi), fontsize=7, color=line.get_color(),
                            textcoords='offset points', xytext=(3, 3))
    ref = case['runs'][0]
    for ax, what in zip(axes, ('max head-top position error [m]', 'final-state error, '
                               'max |q - q_ref| [m, rad]'), strict=True):
        ax.axvline(ref['wall_s'], color='0.6', ls=':', lw=1)
        ax.set_xlabel(f'wall time [s] for {case["duration_s"]:g} s simulated '
                      f'(dotted: reference {ref["wall_s"]:.1f} s)')
        ax.set_ylabel(what)
        ax.grid(True, which='both', alpha=0.3)
    axes[0].axhline(GOAL_HEAD_ERROR, color='r', ls='--', lw=0.8, label='goal 1e-6 m')
    axes[0].axvline(case['duration_s'] / GOAL_RTF, color='r', ls='-.', lw=0.8,
                    label=f'goal {GOAL_RTF:g}x real time')
    axes[0].legend(fontsize=7, ncol=2)
    reference = case['reference']
    fig.suptitle(f'work-precision: {case["title"]}; reference {reference["method"]} rtol '
                 f'{reference["rtol"]:g}', fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(cases: list[dict[str, Any]], headline: dict[str, Any], machine: dict[str, Any],
             ) -> str:
    """Tables of every case plus the headline, as markdown."""
    lines = ['# Work-precision benchmark', '',
             f'Machine: {machine["cpu"]}, {machine["cpus"]} CPUs, Python {machine["python"]}, '
             f'numpy {machine["numpy"]}, pinocchio {machine["pinocchio"]}; '
             f'{machine["date"]}; load average at start {machine["loadavg_start"]}.', '']
    for case in cases:
        events = case['events_in_reference']
        shown = ' '.join(events[:40]) + (f' ... ({len(events)} in all)' if len(events) > 40
                                         else '')
        lines += [f'## {case["name"]}: {case["title"]}', '',
                  f'Events in the reference: {shown or "none"}. A * marks a final state in '
                  'another mode, support side or step than in the reference (q is '
                  'support-rooted, so its error there compares relabelled coordinates).',
                  '', _convergence(case), '',
                  '| method | setting | wall s | RTF | evals/period | transitions | '
                  'head err max m | final q err | final v err | energy drift J | residual | '
                  'status |', '|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|']
        for r in case['runs']:
            name = r['method'] + (' (reference)' if r['reference'] else '')
            drift = f'{r["energy_drift"]:.2e}' if 'energy_drift' in r else '-'
            mark = '' if r['final_discrete_match'] else ' *'
            lines.append(
                f'| {name} | {r["setting"]} | {r["wall_s"]:.2f} | '
                f'{r["rtf"]:.3f} | '
                f'{r["evaluations_per_period"]:.1f} | {r["transitions"]} | '
                f'{r["head_err_max"]:.2e} | {r["final_q_err"]:.2e}{mark} | '
                f'{r["final_v_err"]:.2e} | {drift} | '
                f'{r["residual"]:.1e} | {r["status"][:60]} |')
        lines.append('')
    lines += ['## Headline', '']
    lines += [f'- {line}' for line in headline['lines']]
    return '\n'.join(lines) + '\n'


def machine_info() -> dict[str, Any]:
    """Where the figures were taken."""
    import pinocchio
    cpu = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                cpu = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    return {'cpu': cpu, 'cpus': os.cpu_count(), 'python': platform.python_version(),
            'numpy': np.__version__, 'pinocchio': pinocchio.__version__,
            'platform': platform.platform(), 'date': time.strftime('%Y-%m-%d %H:%M:%S %Z'),
            'loadavg_start': [round(x, 2) for x in os.getloadavg()]}


# --------------------------------------------------------------------------- headline
def headline(cases: list[dict[str, Any]], quick: bool, repeat: int, log) -> dict[str, Any]:
    """Real-time factor of headless stand and skate at their shipped settings, and the goal."""
    from iceskate_bringup.runner import run
    durations = {'stand': 2.5, 'skate': 2.0} if quick else {'stand': None, 'skate': None}
    figures: dict[str, Any] = {}
    for name, duration in durations.items():
        scene = load_scene(name)
        if duration is not None:
            scene = replace(scene, duration=duration)
        rtfs, walls, failure, simulated = [], [], None, 0.0
        for _ in range(repeat):
            try:
                metrics = run(scene, None, progress=False)
            except SimulationError as exc:
                failure = str(exc).splitlines()[0]
                break
            rtfs.append(metrics['real_time_factor'])
            walls.append(metrics['wall_time_s'])
            simulated = metrics['sim_time_s']
            failure = metrics['failure']
        figures[name] = {'sim_time_s': simulated, 'requested_s': scene.duration,
                         'rtf_runs': rtfs,
                         'rtf_median': statistics.median(rtfs) if rtfs else float('nan'),
                         'wall_s_median': statistics.median(walls) if walls else float('nan'),
                         'integrator': scene.simulator.integrator.method,
                         'step': scene.simulator.integrator.step, 'failure': failure}
        log(f'[headline] {name}: {simulated:g} of {scene.duration:g} s simulated, RTF {rtfs} '
            f'({scene.simulator.integrator.method} h={scene.simulator.integrator.step:g})'
            + (f', failure: {failure}' if failure else ''))

    def default_error(case_name: str) -> float | None:
        for case in cases:
            if case['name'] == case_name:
                for r in case['runs']:
                    if r['method'] == 'implicit_euler' and r['step'] == 1e-3:
                        return r['head_err_max']
        return None

    def ran(f: dict[str, Any]) -> str:
        out = f'{f["sim_time_s"]:.3g} of {f["requested_s"]:g} s'
        return out + (f', stopped: {f["failure"][:70]}' if f['failure'] else '')

    lines = [f'headless {name} ({ran(f)}; shipped settings): '
             f'{f["rtf_median"]:.2f}x real time' for name, f in figures.items()]
    for case_name in ('skate', 'events', 'smooth'):
        err = default_error(case_name)
        if err is not None:
            lines.append(
                f'head-trajectory error at the shipped integrator (implicit_euler h=1 ms), '
                f'case {case_name}: {err:.2e} m; goal <= {GOAL_HEAD_ERROR:g} m: '
                + ('met' if err <= GOAL_HEAD_ERROR else
                   f'NOT met ({err / GOAL_HEAD_ERROR:.0f}x too large)'))
    best = _cheapest_meeting_goal(cases)
    if best:
        lines.append(best)
    return {'runs': figures, 'lines': lines}


def _cheapest_meeting_goal(cases: list[dict[str, Any]]) -> str | None:
    """The fastest setting of the eventful cases whose head error meets the goal, with its
    real-time factor (and, for skate, the goal on it)."""
    out = []
    for case in cases:
        if case['name'] not in ('skate', 'events'):
            continue
        swept = [r for r in case['runs'] if not r['reference']]
        ok = [r for r in swept if r['status'] == 'ok' and r['head_err_max'] <= GOAL_HEAD_ERROR]
        if ok:
            r = min(ok, key=lambda r: r['wall_s'])
            goal = ('' if case['name'] != 'skate' else
                    f'; goal >= {GOAL_RTF:g}x: ' + ('met' if r['rtf'] >= GOAL_RTF else 'NOT met'))
            out.append(f'{case["name"]} ({case["duration_s"]:g} s): fastest setting with head '
                       f'error <= 1e-6 m is {r["method"]} {r["setting"]} (error '
                       f'{r["head_err_max"]:.1e} m) at {r["rtf"]:.3f}x real time{goal}')
        elif swept:
            best = min(r['head_err_max'] for r in swept)
            out.append(f'{case["name"]} ({case["duration_s"]:g} s): no swept setting reaches '
                       f'head error <= 1e-6 m (smallest {best:.1e} m)')
    return '; '.join(out) or None


def _convergence(case: dict[str, Any]) -> str:
    """One line: how far the reference has converged (the next looser tolerance's distance)."""
    ref, c = case['reference'], case['reference_converged']
    failed = ''.join(f' (rtol {f["rtol"]:g} stopped: {f["error"][:80]})'
                     for f in ref['failed_tighter'])
    return (f'Reference: {ref["method"]} rtol {ref["rtol"]:g}, atol {ref["atol"]:g}{failed}; '
            f'converged to {c["head_err_max"]:.1e} m head-top error, final q '
            f'{c["final_q_err"]:.1e} (the same run at rtol {c["rtol"]:g}: {c["wall_s"]:.2f} s '
            f'wall, {"the same" if c["same_events"] else "other"} events, {c["status"]}).')


# ------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    """Run the cases, write the outputs, print the headline."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=pathlib.Path, default=REPO_ROOT / 'runs' / 'bench',
                        help='output directory (default runs/bench)')
    parser.add_argument('--quick', action='store_true',
                        help='short spans and sparse sweeps (about 1-2 minutes)')
    parser.add_argument('--cases', help='comma-separated subset of the cases')
    parser.add_argument('--max-run-wall', type=float, default=120.0,
                        help='wall-time limit of one swept run [s] (reference: 4x)')
    parser.add_argument('--repeat', type=int, default=1,
                        help='headline runs per scene (median reported)')
    parser.add_argument('--no-headline', action='store_true', help='skip the headline runs')
    args = parser.parse_args(argv)
    started = time.perf_counter()

    def log(message: str) -> None:
        print(f'{time.perf_counter() - started:7.1f}s {message}', flush=True)

    machine = machine_info()
    cases = make_cases(args.quick)
    if args.cases:
        wanted = set(args.cases.split(','))
        unknown = wanted - {c.name for c in cases}
        if unknown:
            parser.error(f'unknown cases {sorted(unknown)}; one of {[c.name for c in cases]}')
        cases = [c for c in cases if c.name in wanted]
    robot = load_robot()
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for case in cases:
        figures = run_case(case, robot, args.max_run_wall, log)
        results.append(figures)
        png = args.out / f'work_precision_{case.name}.png'
        plot_case(figures, png)
        log(f'[{case.name}] plot {png}')
    head = ({'runs': {}, 'lines': ['headline skipped (--no-headline)']} if args.no_headline
            else headline(results, args.quick, max(1, args.repeat), log))
    elapsed = time.perf_counter() - started
    machine['benchmark_wall_s'] = elapsed
    machine['quick'] = args.quick
    (args.out / 'work_precision.json').write_text(json.dumps(
        {'machine': machine, 'cases': results, 'headline': head}, indent=1,
        default=float) + '\n')
    table = markdown(results, head, machine)
    (args.out / 'work_precision.md').write_text(table)
    print()
    print(table)
    print(f'outputs in {args.out} (work_precision.md, work_precision.json, '
          f'work_precision_<case>.png); {elapsed:.0f} s in all')
    return 0


if __name__ == '__main__':
    sys.exit(main())
