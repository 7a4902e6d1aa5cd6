#!/usr/bin/env python3
"""Where the headless runner's time goes in one control period, on both engines.

Runs the loop of ``run_scene`` on a scene for ``--duration`` s (``Session`` and
``ControlStack``: the observation, the control laws, ``step`` = hold the commands, advance one
period and make its sample, ``flush`` = trajectory row and bag), once on each engine, and times
each part with ``perf_counter``; also the main process's CPU time per period (``process_time``:
the forked bag writer is not in it, and other jobs on the machine do not inflate it as they
inflate wall time). The engines take turns ``--rounds`` times; the figures are the medians.
It prints microseconds per period and part, the real-time factor of each engine and their
ratio, all measured in this one run. ``--no-bag`` writes no bag.

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
from iceskate_bringup.scene import load_scene
from iceskate_sim.robot import Robot, load_robot
from iceskate_sim.scene import Scene
from iceskate_sim.session import Session

PARTS = ('observation', 'control laws', 'step (advance, sample)', 'flush (row, bag)',
         'finish')
ENGINES = ('native', 'python')


def measure(scene: Scene, robot: Robot, bag: bool, directory: pathlib.Path) -> dict[str, float]:
    """Run the loop once; return us per period of each part, the RTF and CPU us per period."""
    out = directory if bag else None
    session = Session(scene, out, out / 'bag' if bag else None, robot)
    stack = ControlStack(scene, session.robot, session.observation())
    spent = dict.fromkeys(PARTS, 0.0)
    clock = time.perf_counter
    cpu_start, wall_start = time.process_time(), clock()
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
    figures['total'] = loop / periods * 1e6
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
    runs: dict[str, list[dict[str, float]]] = {engine: [] for engine in ENGINES}
    for _ in range(args.rounds):
        for engine in ENGINES:
            scene = replace(shipped, simulator=replace(shipped.simulator, engine=engine))
            with tempfile.TemporaryDirectory() as directory:
                runs[engine].append(measure(scene, robot, not args.no_bag,
                                            pathlib.Path(directory)))
    median = {engine: {key: statistics.median(run[key] for run in results)
                       for key in results[0]} for engine, results in runs.items()}
    config = shipped.simulator
    print(f'{args.scene}, {args.duration:g} s, {config.integrator.method} '
          f'{config.integrator.step * 1e3:g} ms, control period {config.control_period * 1e3:g}'
          f' ms, {"no bag" if args.no_bag else "with bag"}; median of {args.rounds} run(s) per '
          f'engine, engines in turn')
    print(f'machine: {info["cpu"]}, {info["cpus"]} CPUs; load average at start '
          f'{info["loadavg_start"]}; {info["date"]}')
    print(f'{"us per control period":<28}' + ''.join(f'{e:>12}' for e in ENGINES))
    for part in (*PARTS, 'total', 'cpu'):
        label = 'CPU of this process' if part == 'cpu' else part
        print(f'{label:<28}' + ''.join(f'{median[e][part]:12.1f}' for e in ENGINES))
    rtf = {engine: median[engine]['rtf'] for engine in ENGINES}
    print(f'real-time factor: native {rtf["native"]:.2f}x, python {rtf["python"]:.2f}x; '
          f'native / python {rtf["native"] / rtf["python"]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
