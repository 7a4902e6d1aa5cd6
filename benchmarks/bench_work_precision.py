#!/usr/bin/env python3
"""Work-precision benchmark of the integrators: wall time against error.

For every engine (native: the C++ core, whole blocks of periods with the laws in C++ where the
method runs natively; python: the readable reference engine), every integrator
(symplectic_euler, implicit_euler, rk4, rk45, dop853) and a sweep of fixed steps or tolerances,
one closed-loop run (the scene's controllers at every control instant, as ``run_scene`` does,
without recording) is timed and compared with a reference run of the same case at the tightest
setting (dop853, rtol 1e-12, atol 1e-14, on the native engine's dynamics). Cases:

* ``smooth``: the ``stand`` scene with the soft joint stops off, 0.4 s before the push: one mode
  (17), no events, visual lifting and the posture impedance running (a smooth right-hand side;
  with the stops on, the elbows rest on their stop at q = 0 and the kink of the stop force
  caps every fixed-step method at first order);
* ``events``: the ``walk`` scene as shipped, 1.28 s: its first step, with support-heel rocking
  (E2, E3), lift-off (S6), heel strike (S1, an impact), heel stop (S2) and sole flat (S4, an
  impact) (the events of the reference run are listed in the outputs);
* ``passive``: the bent-knee double support (mode 17) with no inputs, joint damping and stops
  off, 0.3 s: a conservative system, so the energy drift is the integrator's;
* ``skate`` (full mode only): the ``skate`` scene as shipped, 0.9 s, with its events, for the
  goal figure below (the shipped implicit Euler and the cheap accurate settings of rk4, rk45).

Figures per run, against the reference interpolated onto the run's samples (one per control
period): ``head_err_max`` = max over the samples of |p_head - p_ref| (head-top y, z) [m];
``final_q_err`` / ``final_v_err`` = max abs difference of q / v at the last common sample;
``energy_drift`` = max |E(t) - E(0)| [J] (passive case); ``residual`` = the simulator's largest
constraint residual (measured before each end-of-period projection) [m, rad].

Outputs into ``--out`` (default runs/bench): ``work_precision_<case>.png`` (log-log error against
wall time, one line per method and engine: solid native, dashed python), ``work_precision.md``
(tables) and ``work_precision.json`` (raw figures, machine). Then the headline: real-time
factor of the headless ``stand`` and ``skate`` scenes at their shipped settings
(``iceskate_bringup.runner.run``, no output), and the goal: the cheapest setting of the skate
case with head-trajectory error <= 1e-6 m at >= 5x real time.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_work_precision.py [--out runs/bench] [--quick] [--cases smooth,...]
        [--engines native,python]
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
METHODS = ('symplectic_euler', 'implicit_euler', 'rk4', 'rk45', 'dop853')
FIXED = ('symplectic_euler', 'implicit_euler', 'rk4')
REFERENCE = ('dop853', 1.0e-12)  # method, rtol (atol = 1e-2 rtol)
ENGINES = ('native', 'python')
GOAL_RTF = 5.0  # real-time factor of the cheapest setting within the head-error goal
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
from iceskate_sim.command import HeldCommand  # noqa: E402
from iceskate_sim.dynamics import ContactState  # noqa: E402
from iceskate_sim.errors import SimulationError  # noqa: E402
from iceskate_sim.integrators import IntegratorConfig  # noqa: E402
from iceskate_sim.modes import MODES  # noqa: E402
from iceskate_sim.robot import PIVOTS, SIDES, load_robot  # noqa: E402
from iceskate_sim.scene import Scene  # noqa: E402
from iceskate_sim.simulation import Simulator  # noqa: E402


# ------------------------------------------------------------------------------ driver
@dataclass
class Run:
    """One timed closed-loop run: samples at every control instant (t_0 = start)."""

    label: str
    engine: str
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
    """Fixed-step methods: ``setting`` is the step [s]; adaptive ones: the rtol (atol = 1e-2
    rtol, max step = the control period)."""
    if method in FIXED:
        return IntegratorConfig(method=method, step=setting)
    return IntegratorConfig(method=method, step=period, rtol=setting, atol=setting * 1e-2)


def simulate(scene: Scene, duration: float, integrator: IntegratorConfig | None = None,
             robot: Any = None, max_wall: float = float('inf'), label: str = '',
             energy: bool = False, stack_class: type = ControlStack,
             **config_changes: Any) -> Run:
    """Run ``scene`` for ``duration`` [s] the way ``run_scene`` does (same control stack,
    pushes, zero-order hold; on the native engine the same native blocks of periods), without
    recording; stop after ``max_wall`` s of wall time.

    :param integrator: replaces the scene's integrator (None: keep it).
    :param stack_class: the controllers (``ControlStack`` or a variant with its signature).
    :param config_changes: other ``SimulatorConfig`` fields to replace (e.g. projection).
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
    samples = [(sim.state.t, sim.state.q.copy(), sim.state.v.copy(), sim.state.contact,
                sim.state.step_index)]
    obs = sim.observation()
    loop = sim.control_loop(stack.kinematics, list(stack.controllers.values()), scene.pushes,
                            sim.dynamics.head_pose(obs.contact(), obs.q)[0])
    start = time.perf_counter()
    if loop is not None:
        blocks, error = _native_blocks(sim, loop, n_periods, start, max_wall)
        wall = time.perf_counter() - start
        # the state each period started from (after the transitions due then), then the last
        samples = [(t, q, v, ContactState(MODES[mode], SIDES[side], PIVOTS[pivot]), step)
                   for b in blocks for t, q, v, mode, side, pivot, step in zip(
                       b['t'], b['q'], b['v'], b['mode'].tolist(), b['side'].tolist(),
                       b['pivot'].tolist(), b['step_index'].tolist(), strict=True)]
        samples.append((sim.state.t, sim.state.q.copy(), sim.state.v.copy(), sim.state.contact,
                        sim.state.step_index))
    else:
        error = None
        try:
            for _ in range(n_periods):
                t = sim.state.t
                commands = stack.commands(sim.observation())
                push = next(((p.frame, np.array(p.force)) for p in scene.pushes
                             if p.active(t)), None)
                sim.advance(HeldCommand.of_controllers(commands.values()), push)
                samples.append((sim.state.t, sim.state.q.copy(), sim.state.v.copy(),
                                sim.state.contact, sim.state.step_index))
                if sim.ended is not None:
                    break
                if time.perf_counter() - start > max_wall:
                    error = f'wall-time limit {max_wall:g} s reached at t={sim.state.t:.4f} s'
                    break
        except SimulationError as exc:
            error = str(exc).splitlines()[0][:200]
        wall = time.perf_counter() - start
    dyn = sim.dynamics
    head = np.array([dyn.frame_placement(c, q, 'head_top').translation[1:3]
                     for _, q, _, c, _ in samples])
    energies = (np.array([sum(dyn.energy(c, q, v)) for _, q, v, c, _ in samples]) if energy
                else np.full(len(samples), np.nan))
    integ = cfg.integrator
    discrete = np.array([(c.mode.number, c.side == 'left', step) for _, _, _, c, step
                         in samples], dtype=int)
    return Run(label, cfg.engine, integ.method, integ.step, integ.rtol, wall,
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
    if quick:
        return [
            Case('smooth', 'stand, soft stops off, mode 17, 0.1 s (no events)', smooth, 0.1, {
                'symplectic_euler': (5e-5, 2.5e-5), 'implicit_euler': (1e-3, 2.5e-4),
                'rk4': (1e-4, 5e-5), 'rk45': (1e-4, 1e-8), 'dop853': (1e-5, 1e-9)}),
            Case('events', 'walk as shipped, 0.6 s (with events)', walk, 0.6, {
                'implicit_euler': (1e-3, 2.5e-4), 'rk4': (1e-4,), 'dop853': (1e-7,)}),
            Case('passive', 'mode 17, no inputs, no damping/stops, 0.2 s', passive, 0.2, {
                'symplectic_euler': (1e-3, 2.5e-4), 'implicit_euler': (1e-3,),
                'rk4': (1e-3, 2.5e-4), 'rk45': (1e-6,), 'dop853': (1e-8,)}, energy=True),
        ]
    return [
        Case('smooth', 'stand, soft stops off, mode 17, 0.4 s (no events)', smooth, 0.4, {
            'symplectic_euler': (1e-4, 5e-5, 2.5e-5, 1e-5),
            'implicit_euler': (1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5),
            'rk4': (1e-4, 5e-5, 2.5e-5),
            'rk45': (1e-3, 1e-5, 1e-7, 1e-9),
            'dop853': (1e-4, 1e-6, 1e-8, 1e-10)}),
        Case('events', 'walk as shipped, 1.28 s (first step, with events)', walk, 1.28, {
                 'symplectic_euler': (5e-5, 2.5e-5),
                 'implicit_euler': (1e-3, 5e-4, 2.5e-4, 1e-4),
                 'rk4': (1e-4, 5e-5, 2.5e-5),
                 'rk45': (1e-4, 1e-6, 1e-8),
                 'dop853': (1e-5, 1e-7, 1e-9)}),
        Case('passive', 'mode 17, no inputs, joint damping and stops off, 0.3 s', passive, 0.3,
             {'symplectic_euler': (1e-3, 5e-4, 2.5e-4, 1e-4),
              'implicit_euler': (1e-3, 5e-4, 2.5e-4, 1e-4),
              'rk4': (1e-3, 5e-4, 2.5e-4),
              'rk45': (1e-4, 1e-6, 1e-8),
              'dop853': (1e-5, 1e-7, 1e-9)}, energy=True),
        Case('skate', 'skate as shipped, 0.9 s (with events)', load_scene('skate'), 0.9,
             {'implicit_euler': (1e-3, 2.5e-4, 1e-4), 'rk4': (2e-4, 1e-4, 5e-5),
              'rk45': (1e-2, 1e-3, 1e-4)}),
    ]


def run_case(case: Case, robot: Any, max_wall: float, engines: tuple[str, ...],
             log) -> dict[str, Any]:
    """Reference plus sweep of one case on each engine; returns its JSON figures."""
    period = case.scene.simulator.control_period
    ref = simulate(case.scene, case.duration, integrator_config(REFERENCE[0], REFERENCE[1],
                                                                  period),
                   robot, max_wall * 4, 'reference', case.energy, engine='native')
    log(f'[{case.name}] reference {REFERENCE[0]} rtol {REFERENCE[1]:g}: {ref.wall:.1f} s wall, '
        f'{ref.evaluations} evaluations, {ref.transitions} transitions '
        f'{" ".join(ref.events[:30])}{" ..." if len(ref.events) > 30 else ""}, {ref.status}')
    rows = [_row(ref, ref, period)]
    for engine in engines:
        for method in METHODS:
            for setting in case.sweep.get(method, ()):
                try:
                    integ = integrator_config(method, setting, period)
                except SimulationError as exc:
                    log(f'[{case.name}] {method} {setting:g}: skipped ({exc})')
                    continue
                run = simulate(case.scene, case.duration, integ, robot, max_wall,
                               f'{method} {setting:g}', case.energy, engine=engine)
                row = _row(run, ref, period)
                rows.append(row)
                log(f'[{case.name}] {engine:6s} {method:16s} {_setting(method, setting):>11s} '
                    f'{run.wall:7.2f} s ({row["rtf"]:6.2f}x)  head {row["head_err_max"]:.2e} m'
                    f'  final q {row["final_q_err"]:.2e}  residual {run.residual:.1e}  '
                    f'{run.status}')
    return {'name': case.name, 'title': case.title, 'duration_s': case.duration,
            'reference': {'method': REFERENCE[0], 'rtol': REFERENCE[1],
                          'atol': REFERENCE[1] * 1e-2},
            'events_in_reference': ref.events, 'runs': rows}


def _setting(method: str, setting: float) -> str:
    return f'h={setting:g}' if method in FIXED else f'rtol={setting:g}'


def _row(run: Run, ref: Run, period: float) -> dict[str, Any]:
    setting = run.step if run.method in FIXED else run.rtol
    row = {'engine': run.engine, 'method': run.method,
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
    for engine, method in ((e, m) for e in ENGINES for m in METHODS):
        rows = [r for r in case['runs'] if r['method'] == method and r['engine'] == engine
                and not r['reference']]
        if not rows:
            continue
        for ax, key in zip(axes, ('head_err_max', 'final_q_err'), strict=True):
            x = [r['wall_s'] for r in rows]
            y = [max(r[key], ERROR_FLOOR) for r in rows]
            line, = ax.loglog(x, y, 'o-' if engine == 'native' else 's--',
                              color=colours[method], label=f'{method} ({engine})')
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
    fig.suptitle(f'work-precision: {case["title"]}; reference dop853 rtol 1e-12', fontsize=10)
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
                  '', '| engine | method | setting | wall s | RTF | evals/period | transitions | '
                  'head err max m | final q err | final v err | energy drift J | residual | '
                  'status |', '|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|']
        for r in case['runs']:
            name = r['method'] + (' (reference)' if r['reference'] else '')
            drift = f'{r["energy_drift"]:.2e}' if 'energy_drift' in r else '-'
            mark = '' if r['final_discrete_match'] else ' *'
            lines.append(
                f'| {r["engine"]} | {name} | {r["setting"]} | {r["wall_s"]:.2f} | '
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
                    if (r['method'] == 'implicit_euler' and r['step'] == 1e-3
                            and r['engine'] == 'native'):
                        return r['head_err_max']
        return None

    def ran(f: dict[str, Any]) -> str:
        out = f'{f["sim_time_s"]:.3g} of {f["requested_s"]:g} s'
        return out + (f', stopped: {f["failure"][:70]}' if f['failure'] else '')

    lines = [f'headless {name} ({ran(f)}; shipped settings, native engine): '
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
    """The fastest setting of the eventful cases whose head error meets the goal, per engine,
    and the ratio of the two engines' figures."""
    out = []
    for case in cases:
        if case['name'] not in ('skate', 'events'):
            continue
        rtf = {}
        for engine in ENGINES:
            swept = [r for r in case['runs'] if not r['reference'] and r['engine'] == engine]
            if not swept:
                continue
            ok = [r for r in swept if r['status'] == 'ok' and r['head_err_max'] <= GOAL_HEAD_ERROR]
            if ok:
                r = min(ok, key=lambda r: r['wall_s'])
                rtf[engine] = r['rtf']
                goal = ('' if case['name'] != 'skate' else
                        f'; goal >= {GOAL_RTF:g}x: '
                        + ('met' if r['rtf'] >= GOAL_RTF else 'NOT met'))
                out.append(f'{case["name"]}, {engine} engine: fastest setting with head error '
                           f'<= 1e-6 m is {r["method"]} {r["setting"]} at {r["rtf"]:.3f}x real '
                           f'time{goal}')
            else:
                out.append(f'{case["name"]}, {engine} engine: no swept setting reaches head '
                           f'error <= 1e-6 m')
        if len(rtf) == 2:
            out.append(f'{case["name"]}: native / python at that goal = '
                       f'{rtf["native"] / rtf["python"]:.1f}x')
    return '; '.join(out) or None


# ------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    """Run the cases, write the outputs, print the headline."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=pathlib.Path, default=REPO_ROOT / 'runs' / 'bench',
                        help='output directory (default runs/bench)')
    parser.add_argument('--quick', action='store_true',
                        help='short spans and sparse sweeps (about 1-2 minutes)')
    parser.add_argument('--cases', help='comma-separated subset of the cases')
    parser.add_argument('--engines', default=','.join(ENGINES),
                        help='comma-separated engines to sweep (default native,python)')
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
    engines = tuple(args.engines.split(','))
    if set(engines) - set(ENGINES):
        parser.error(f'--engines takes a comma-separated subset of {ENGINES}')
    robot = load_robot()
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for case in cases:
        figures = run_case(case, robot, args.max_run_wall, engines, log)
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
