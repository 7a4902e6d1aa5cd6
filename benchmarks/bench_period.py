#!/usr/bin/env python3
"""Where the headless runner's time goes in one control period: the native loop and both engines
period by period.

Runs ``--duration`` s of a scene three ways, in turn, ``--rounds`` times (medians):

* ``native loop``: what ``run_scene`` does (``Session.run_periods`` in blocks of
  ``BLOCK_PERIODS``): observation, control laws, zero-order hold, period and sample in one C++
  call per block (``iceskate_native.ControlLoop``), then the block recorded (trajectory, bag);
* ``native, per period`` and ``python, per period``: the loop the ROS simulator node runs
  (``Session.step`` with the commands of ``ControlStack``), on each engine: the observation,
  the control laws, ``step`` (hold the commands, advance one period, make its sample) and
  ``flush`` (trajectory row, bag) timed apart.

It prints microseconds per period and part, the CPU time of this process per period (the forked
bag writer is not in it), the real-time factors and their ratios, all measured in this one run.
``--no-bag`` writes no bag.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_period.py [skate] [--duration 15] [--rounds 1] [--no-bag]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import pathlib
import statistics
import sys
import tempfile
import time

from bench_work_precision import machine_info

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import BLOCK_PERIODS
from iceskate_bringup.scene import load_scene
from iceskate_sim.robot import Robot, load_robot
from iceskate_sim.scene import Scene
from iceskate_sim.session import Session

PARTS = ('observation', 'control laws', 'step (advance, sample)', 'flush (row, bag)',
         'native block (laws, periods, samples)', 'block recorded (trajectory, bag)', 'finish')
VARIANTS = ('native loop', 'native, per period', 'python, per period')


def measure(scene: Scene, robot: Robot, bag: bool, directory: pathlib.Path,
            blocks: bool) -> dict[str, float]:
    """Run the loop once (``blocks``: the runner's native blocks, else period by period); return
    us per period of each part, the total, the CPU of this process and the RTF."""
    out = directory if bag else None
    session = Session(scene, out, out / 'bag' if bag else None, robot)
    stack = ControlStack(scene, session.robot, session.observation())
    spent = dict.fromkeys(PARTS, 0.0)
    clock = time.perf_counter
    cpu_start, wall_start = time.process_time(), clock()
    if blocks:
        run_loop = session.sim.run_loop

        def timed_loop(*args: object) -> object:
            start = clock()
            try:
                return run_loop(*args)
            finally:
                spent['native block (laws, periods, samples)'] += clock() - start

        session.sim.run_loop = timed_loop  # type: ignore[method-assign]
        while not session.done:
            session.run_periods(stack, BLOCK_PERIODS)
        spent['block recorded (trajectory, bag)'] = (
            clock() - wall_start - spent['native block (laws, periods, samples)'])
    while not session.done:
        t0 = clock()
        obs = session.observation()
        t1 = clock()
        commands = stack.commands(obs)
        t2 = clock()
        session.step(commands)
        t3 = clock()
        session.flush()
        t4 = clock()
        spent['observation'] += t1 - t0
        spent['control laws'] += t2 - t1
        spent['step (advance, sample)'] += t3 - t2
        spent['flush (row, bag)'] += t4 - t3
    loop = clock() - wall_start
    cpu = time.process_time() - cpu_start
    t5 = clock()
    session.finish()
    spent['finish'] = clock() - t5
    if session.error is not None or session.sim.ended is not None:
        raise SystemExit(f'the {scene.simulator.engine} run stopped at t={session.sim.time:.3f} s'
                         f' ({session.error or session.sim.ended})')
    periods = session.periods
    figures = {part: seconds / periods * 1e6 for part, seconds in spent.items()}
    figures['total'] = (loop + spent['finish']) / periods * 1e6
    figures['cpu'] = cpu / periods * 1e6
    figures['rtf'] = scene.duration / (loop + spent['finish'])
    return figures


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--duration', type=float, default=15.0, help='simulated time [s]')
    parser.add_argument('--rounds', type=int, default=1, help='runs per engine (median)')
    parser.add_argument('--no-bag', action='store_true', help='write no bag')
    args = parser.parse_args(argv)
    info = machine_info()
    robot = load_robot()
    shipped = replace(load_scene(args.scene), duration=args.duration)
    runs: dict[str, list[dict[str, float]]] = {variant: [] for variant in VARIANTS}
    for _ in range(args.rounds):
        for variant in VARIANTS:
            engine = variant.split(',')[0].split()[0]
            scene = replace(shipped, simulator=replace(shipped.simulator, engine=engine))
            with tempfile.TemporaryDirectory() as directory:
                runs[variant].append(measure(scene, robot, not args.no_bag,
                                             pathlib.Path(directory), variant == 'native loop'))
    median = {variant: {key: statistics.median(run[key] for run in results)
                        for key in results[0]} for variant, results in runs.items()}
    config = shipped.simulator
    print(f'{args.scene}, {args.duration:g} s, {config.integrator.method} '
          f'{config.integrator.step * 1e3:g} ms, control period {config.control_period * 1e3:g}'
          f' ms, {"no bag" if args.no_bag else "with bag"}; median of {args.rounds} run(s) per '
          f'variant, variants in turn')
    print(f'machine: {info["cpu"]}, {info["cpus"]} CPUs; load average at start '
          f'{info["loadavg_start"]}; {info["date"]}')
    print(f'{"us per control period":<38}' + ''.join(f'{v:>20}' for v in VARIANTS))
    for part in (*PARTS, 'total', 'cpu'):
        label = 'CPU of this process' if part == 'cpu' else part
        print(f'{label:<38}' + ''.join(
            f'{median[v][part]:20.1f}' if median[v][part] else f'{"-":>20}' for v in VARIANTS))
    rtf = {variant: median[variant]['rtf'] for variant in VARIANTS}
    print('real-time factor: ' + ', '.join(f'{v} {rtf[v]:.2f}x' for v in VARIANTS))
    base = rtf['python, per period']
    print('ratios to python, per period: ' + ', '.join(
        f'{v} {rtf[v] / base:.2f}' for v in VARIANTS[:2]))
    return 0


if __name__ == '__main__':
    sys.exit(main())
