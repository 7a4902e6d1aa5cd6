#!/usr/bin/env python3
"""Where the headless runner's time goes in one control period.

Runs the loop of ``run_scene`` (observation, control laws, ``advance_and_sample``, trajectory
row, bag) on a scene for ``--duration`` s and times each part with ``perf_counter``; also the
main process's CPU time per period (``process_time``: the forked bag writer is not in it, and
other jobs on the machine do not inflate it as they inflate wall time). ``--inline-bag``
writes the bag in-process (as before the writer process), ``--no-bag`` writes none.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_period.py [stand] [--duration 3] [--inline-bag | --no-bag]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import pathlib
import sys
import tempfile
import time

from bench_work_precision import machine_info

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import advance_and_sample, scene_metadata
from iceskate_bringup.scene import load_scene
from iceskate_sim.metrics import Trajectory
from iceskate_sim.recording import BagRecorder
from iceskate_sim.robot import load_robot
from iceskate_sim.simulation import Simulator

PARTS = ('observation', 'control laws', 'advance and sample', 'trajectory row', 'bag write',
         'bag close')


def measure(scene_name: str, duration: float, bag: str, directory: pathlib.Path) -> None:
    """Run the loop and print wall time per period and part [us], RTF and CPU per period."""
    scene = replace(load_scene(scene_name), duration=duration)
    robot = load_robot()
    sim = Simulator(robot, scene.simulator, scene.initial)
    stack = ControlStack(scene, robot, sim.observation())
    trajectory = Trajectory()
    recorder = (None if bag == 'none' else
                BagRecorder(directory / 'bag', scene_metadata(scene),
                            robot.urdf_path.read_text(encoding='utf-8'),
                            background=bag == 'background'))
    spent = dict.fromkeys(PARTS, 0.0)
    clock = time.perf_counter
    periods = 0
    wall0, cpu0 = clock(), time.process_time()
    for _ in range(int(round(scene.duration / scene.simulator.control_period))):
        t0 = clock()
        obs = sim.observation()
        t1 = clock()
        commands = stack.commands(obs)
        t2 = clock()
        sample = advance_and_sample(sim, scene, commands)
        t3 = clock()
        trajectory.append(sample, stack.last_psi_d)
        t4 = clock()
        if recorder is not None:
            recorder.write(sample)
        t5 = clock()
        for part, dt in zip(PARTS[:5], (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4),
                            strict=True):
            spent[part] += dt
        periods += 1
        if sim.ended is not None:
            break
    t0 = clock()
    if recorder is not None:
        recorder.close()
    spent['bag close'] = clock() - t0
    wall, cpu = clock() - wall0, time.process_time() - cpu0
    print(f'{scene.name}, bag {bag}: {periods} periods, {sim.stats.evaluations / periods:.2f} '
          f'evaluations/period; wall {1e6 * wall / periods:.0f} us/period (real-time factor '
          f'{sim.time / wall:.2f}), main-process CPU {1e6 * cpu / periods:.0f} us/period')
    for part in PARTS:
        print(f'  {part:20s} {1e6 * spent[part] / periods:7.1f} us/period '
              f'{100 * spent[part] / wall:5.1f} %')


def main(argv: list[str] | None = None) -> int:
    """Console entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('scene', nargs='?', default='stand')
    parser.add_argument('--duration', type=float, default=3.0, help='simulated time [s]')
    group = parser.add_mutually_exclusive_group()
    group.add_argument('--inline-bag', action='store_true', help='write the bag in-process')
    group.add_argument('--no-bag', action='store_true', help='write no bag')
    args = parser.parse_args(argv)
    bag = 'none' if args.no_bag else 'inline' if args.inline_bag else 'background'
    print(machine_info())
    with tempfile.TemporaryDirectory() as directory:
        measure(args.scene, args.duration, bag, pathlib.Path(directory))
    return 0


if __name__ == '__main__':
    sys.exit(main())
