#!/usr/bin/env python3
"""The control laws of one control period: what the native laws cost, and where.

Runs a scene headless for ``--duration`` s (``Session`` with ``ControlStack``, the native laws)
and, at every control instant, times the laws two ways on the same observation:
``native_values`` of each controller (what the nodes pay: the observation converted, the C++
laws, the answer as the ``CommandValues`` a node sends) and the bare
``Controller.compute`` calls (the C++ laws and the binding's conversions, with a native
observation made once per period; the laws' kinematics answers the second call at the same
state from its cache, so this is what the laws cost beyond the Pinocchio passes). Prints
microseconds per period (medians of the per-period times, and means) and each way's share of
``native_values``, all measured in this one run.

Usage (from the repository root, environment sourced; under the machine's CPU lock):
    python benchmarks/bench_laws.py [skate] [--duration 15]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import statistics
import time

from bench_period import answers
from bench_work_precision import machine_info

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene
from iceskate_sim.physics.native_control import native_observation
from iceskate_sim.run.session import Session

STACK, COMPUTE = 'native laws (native_values)', 'native laws (Controller.compute)'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--duration', type=float, default=15.0, help='simulated seconds')
    args = parser.parse_args()
    scene = replace(load_scene(args.scene), duration=args.duration)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    ways = [STACK, COMPUTE]
    times: dict[str, list[float]] = {way: [] for way in ways}
    clock = time.perf_counter
    while not session.done:
        obs = session.observation()
        t0 = clock()
        answers(stack, obs)
        t1 = clock()
        native = native_observation(obs)
        for controller in stack.controllers.values():
            controller.compute(native, stack.kinematics)
        t2 = clock()
        times[STACK].append((t1 - t0) * 1e6)
        times[COMPUTE].append((t2 - t1) * 1e6)
        session.run_periods(stack, 1)  # the period (its laws again in C++, not timed)
    periods = len(times[STACK])
    cpu = machine_info()['cpu']
    print(f'{args.scene}: {periods} control periods ({args.duration:g} s) on {cpu}')
    print(f'{"laws of one period":<40} {"median us":>10} {"mean us":>10} {"of the stack":>13}')
    stack_median = statistics.median(times[STACK])
    for way in ways:
        median = statistics.median(times[way])
        print(f'{way:<40} {median:10.1f} {statistics.fmean(times[way]):10.1f} '
              f'{median / stack_median:13.2f}')


if __name__ == '__main__':
    main()
