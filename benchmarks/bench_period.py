#!/usr/bin/env python3
"""Where the headless run's time goes in one control period: the native loop, the whole run as
metrics.json reports it, with and without a bag, and the periods one at a time.

Runs ``--duration`` s of a scene three ways, in turn, ``--rounds`` times (medians):

* ``run, no bag`` and ``run, with bag``: what ``run_scene SCENE --out DIR`` does
  (``iceskate_bringup.runner.simulate`` into a temporary folder: ``Session.run_periods`` in
  blocks of ``BLOCK_PERIODS``, the trajectory, metrics, events and, unless ``--no-picture``,
  summary.png). Timed apart: the native blocks (``Simulator.run_loop``: observation, control
  laws, zero-order hold, period and sample in one C++ call per block), the blocks recorded
  (``Session._record_block``: trajectory, bag hand-over) and ``Session.finish``. Two real-time
  factors per run: the native loop's (simulated time over the time in the native blocks) and the
  run's own, ``real_time_factor`` as metrics.json reports it (from the first block to the
  metrics: recording and outputs included); the project's goal is the run's own >= 80 % of the
  loop's;
* ``per period (inbox)``: the periods one at a time the way the ROS simulator node runs them,
  without the messaging: the observation, the control laws (``native_values``), each
  controller's command into the native loop's inbox (``Session.command_inbox``, ``receive``),
  ``Session.hold`` (one period) and ``Session.flush`` (a block of samples at a time), no bag.

It prints microseconds per period and part, the CPU time of this process per period (the forked
bag writer is not in it), the real-time factors and their ratios, all measured in this one run.
A short run of each variant first (``WARMUP``, not counted) takes the imports and the first
native calls out of the figures. ``--no-bag`` leaves out the run with a bag.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_period.py [skate] [--duration 15] [--rounds 1] [--no-bag]
        [--no-picture]
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
import contextlib
from dataclasses import replace
import json
import pathlib
import statistics
import sys
import tempfile
import time

from bench_work_precision import machine_info

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import simulate
from iceskate_bringup.scene import load_scene
from iceskate_sim.model.command import CommandValues
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import Robot, load_robot
from iceskate_sim.physics.native_control import native_observation, native_values
from iceskate_sim.physics.simulation import Simulator
from iceskate_sim.run.scene import Scene
from iceskate_sim.run.session import Session


def answers(stack: ControlStack, obs: Observation) -> dict[str, CommandValues]:
    """What each controller node of ``stack`` sends at ``obs`` (as the nodes compute it)."""
    native = native_observation(obs)
    return {node: native_values(controller, native, stack.kinematics)
            for node, controller in stack.controllers.items()}


GOAL = 0.8  # the run's own real-time factor over the native loop's
#: the run's own real-time factor (metrics.json) sought on the 15 s skate scene
RTF_GOAL = {'run, no bag': 100.0, 'run, with bag': 50.0}
WARMUP = 0.1  # s simulated of each variant before the timed runs
RUN_PARTS = ('native blocks (laws, periods, samples)', 'blocks recorded (trajectory, bag)')
PERIOD_PARTS = ('observation', 'control laws (native_values)',
                'commands into the inbox', 'hold (one period)', 'flush (samples recorded)')
PARTS = (*PERIOD_PARTS, *RUN_PARTS, 'finish (outputs, metrics, bag closed)')
NO_BAG, WITH_BAG, PER_PERIOD = 'run, no bag', 'run, with bag', 'per period (inbox)'


@contextlib.contextmanager
def timed(owner: type, name: str, spent: dict[str, float], part: str) -> Iterator[None]:
    """Add the wall time of every call of ``owner.name`` to ``spent[part]`` while inside."""
    original = getattr(owner, name)
    clock = time.perf_counter

    def wrapper(*args: object, **kwargs: object) -> object:
        start = clock()
        try:
            return original(*args, **kwargs)
        finally:
            spent[part] += clock() - start

    setattr(owner, name, wrapper)
    try:
        yield
    finally:
        setattr(owner, name, original)


def _figures(spent: dict[str, float], periods: int, total: float, cpu: float,
             metrics: dict) -> dict[str, float]:
    """us per period of each part, the total and the CPU; the real-time factors."""
    figures = {part: seconds / periods * 1e6 for part, seconds in spent.items()}
    figures['total'] = total / periods * 1e6
    figures['cpu'] = cpu / periods * 1e6
    figures['rtf'] = metrics['real_time_factor']
    native = spent['native blocks (laws, periods, samples)']
    figures['loop_rtf'] = metrics['sim_time_s'] / native if native else 0.0
    return figures


def measure_run(scene: Scene, directory: pathlib.Path, picture: bool) -> dict[str, float]:
    """``run_scene``'s run into ``directory`` (its bag if the scene records one), the parts
    timed; the real-time factor read back from its metrics.json."""
    spent = dict.fromkeys(PARTS, 0.0)
    clock = time.perf_counter
    with contextlib.ExitStack() as stack:
        stack.enter_context(timed(Simulator, 'run_loop', spent, RUN_PARTS[0]))
        stack.enter_context(timed(Session, '_record_block', spent, RUN_PARTS[1]))
        stack.enter_context(timed(Session, 'finish', spent, PARTS[-1]))
        cpu_start, wall_start = time.process_time(), clock()
        outcome = simulate(scene, directory, progress=False, picture=picture)
        metrics, error = outcome.metrics, outcome.error
        total, cpu = clock() - wall_start, time.process_time() - cpu_start
    if error is not None or metrics['failure']:
        raise SystemExit(f'the run stopped at t={metrics["sim_time_s"]:.3f} s '
                         f'({error or metrics["failure"]})')
    reported = json.loads((directory / 'metrics.json').read_text())
    periods = int(round(reported['sim_time_s'] / scene.simulator.control_period))
    return _figures(spent, periods, total, cpu, reported)


def measure_per_period(scene: Scene, robot: Robot, directory: pathlib.Path) -> dict[str, float]:
    """The periods one at a time through the command inbox (the simulator node's path without
    messages), no bag; the real-time factor read back from its metrics.json."""
    spent = dict.fromkeys(PARTS, 0.0)
    clock = time.perf_counter
    cpu_start, wall_start = time.process_time(), clock()
    session = Session(scene, directory, None, robot)
    stack = ControlStack(scene, session.robot, session.observation())
    first = answers(stack, session.observation())
    inbox = session.command_inbox(tuple(values.sources for values in first.values()))
    while not session.done:
        t0 = clock()
        obs = session.observation()
        t1 = clock()
        commands = answers(stack, obs)
        t2 = clock()
        for index, values in enumerate(commands.values()):
            inbox.receive(index, values)
        t3 = clock()
        session.hold()
        t4 = clock()
        session.flush(whole=False)
        t5 = clock()
        for part, seconds in zip(PERIOD_PARTS, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4),
                                 strict=True):
            spent[part] += seconds
    t6 = clock()
    session.finish()
    spent[PARTS[-1]] = clock() - t6
    total, cpu = clock() - wall_start, time.process_time() - cpu_start
    if session.error is not None or session.sim.ended is not None:
        raise SystemExit(f'the per-period run stopped at t={session.sim.time:.3f} s'
                         f' ({session.error or session.sim.ended})')
    return _figures(spent, session.periods, total, cpu, session.metrics)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--duration', type=float, default=15.0, help='simulated time [s]')
    parser.add_argument('--rounds', type=int, default=1, help='runs per variant (median)')
    parser.add_argument('--no-bag', action='store_true', help='leave out the run with a bag')
    parser.add_argument('--no-picture', action='store_true',
                        help='no summary.png in the runs (run_scene draws it)')
    args = parser.parse_args(argv)
    info = machine_info()
    robot = load_robot()
    shipped = replace(load_scene(args.scene), duration=args.duration)
    scenes = {NO_BAG: replace(shipped, record_bag=False)}
    if not args.no_bag:
        scenes[WITH_BAG] = replace(shipped, record_bag=True)
    variants = (*scenes, PER_PERIOD)
    runs: dict[str, list[dict[str, float]]] = {variant: [] for variant in variants}

    def measure(variant: str, duration: float) -> dict[str, float]:
        with tempfile.TemporaryDirectory() as directory:
            out = pathlib.Path(directory) / 'out'
            if variant == PER_PERIOD:
                return measure_per_period(replace(shipped, record_bag=False, duration=duration),
                                          robot, out)
            return measure_run(replace(scenes[variant], duration=duration), out,
                               not args.no_picture)

    for variant in variants:  # warm-up (imports, first native calls), not counted
        measure(variant, min(args.duration, WARMUP))
    for _ in range(args.rounds):
        for variant in variants:
            runs[variant].append(measure(variant, args.duration))
    median = {variant: {key: statistics.median(run[key] for run in results)
                        for key in results[0]} for variant, results in runs.items()}
    config = shipped.simulator
    print(f'{args.scene}, {args.duration:g} s, {config.integrator.method} '
          f'{config.integrator.step * 1e3:g} ms, control period {config.control_period * 1e3:g}'
          f' ms; median of {args.rounds} run(s) per variant, variants in turn'
          f'{"" if args.no_picture else "; the runs draw summary.png (in finish)"}')
    print(f'machine: {info["cpu"]}, {info["cpus"]} CPUs; load average at start '
          f'{info["loadavg_start"]}; {info["date"]}')
    print(f'{"us per control period":<40}' + ''.join(f'{v:>20}' for v in variants))
    for part in (*PARTS, 'total', 'cpu'):
        label = {'cpu': 'CPU of this process',
                 'total': 'total (start-up to exit)'}.get(part, part)
        print(f'{label:<40}' + ''.join(
            f'{median[v][part]:20.1f}' if median[v][part] else f'{"-":>20}' for v in variants))
    runs_only = [v for v in variants if v != PER_PERIOD]
    print('real-time factor: ' + ', '.join(
        f'native loop ({v.removeprefix("run, ")}) {median[v]["loop_rtf"]:.2f}x, '
        f'the run, metrics.json ({v.removeprefix("run, ")}) {median[v]["rtf"]:.2f}x'
        for v in runs_only) + f', {PER_PERIOD}, metrics.json {median[PER_PERIOD]["rtf"]:.2f}x')
    print(f"the run's own / the native loop's (goal >= {GOAL:.0%}): " + ', '.join(
        f'{v.removeprefix("run, ")} {median[v]["rtf"] / median[v]["loop_rtf"]:.0%} '
        f'({"met" if median[v]["rtf"] >= GOAL * median[v]["loop_rtf"] else "NOT met"})'
        for v in runs_only))
    print("the run's own real-time factor: " + ', '.join(
        f'{v.removeprefix("run, ")} {median[v]["rtf"]:.1f}x (goal >= {RTF_GOAL[v]:g}x: '
        f'{"met" if median[v]["rtf"] >= RTF_GOAL[v] else "NOT met"})' for v in runs_only))
    base = median[NO_BAG]['rtf']
    print('ratios to the run without bag (metrics.json): ' + ', '.join(
        f'{v} {median[v]["rtf"] / base:.2f}' for v in variants[1:]))
    return 0


if __name__ == '__main__':
    sys.exit(main())
