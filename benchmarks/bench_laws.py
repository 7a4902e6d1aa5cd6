#!/usr/bin/env python3
"""The control laws of one control period: the Python references against the native laws.

Runs a scene headless for ``--duration`` s (``Session`` with ``ControlStack``, the native laws)
and, at every control instant, also times the Python reference laws
(``visual_lifting.law.visual_lifting`` and ``gait_manager.law.gait_manager_commands`` with
``ControllerCommand.of``, what ``ControlStack`` computed before the laws went native) on the same
observation. The native laws are timed two ways: ``ControlStack.commands`` (what the headless
runner and the nodes pay: the observation converted, the C++ laws, the answer turned into
``ControllerCommand`` objects) and the bare ``Controller.compute`` calls (the C++ laws and the
binding's conversions, with a native observation made once per period). Prints microseconds per
period (medians of the per-period times, and means) and the ratios, all measured in this one run.

Usage (from the repository root, environment sourced; under the machine's CPU lock):
    python benchmarks/bench_laws.py [skate] [--duration 15]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import statistics
import time

from bench_work_precision import machine_info

from gait_manager.law import gait_manager_commands
from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene, node_parameters
from iceskate_sim.command import ControllerCommand, JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.native_control import native_observation
from iceskate_sim.session import Session
from visual_lifting.law import head_origin, visual_lifting

WAYS = ('Python laws', 'native laws (ControlStack.commands)', 'native laws (Controller.compute)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--duration', type=float, default=15.0, help='simulated seconds')
    args = parser.parse_args()
    scene = replace(load_scene(args.scene), duration=args.duration)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    params = node_parameters(scene)
    lifting, gait = params.get('visual_lifting'), params.get('gait_manager')
    dynamics = GaitDynamics(session.robot)
    origin = head_origin(session.observation(), dynamics)
    times: dict[str, list[float]] = {way: [] for way in WAYS}
    clock = time.perf_counter
    while not session.done:
        obs = session.observation()
        t0 = clock()
        if lifting is not None:
            task = visual_lifting(obs, dynamics, lifting, origin)
            ControllerCommand.of({'visual_lifting': JointCommand(task.tau)}, obs.q, obs.v,
                                 task.psi_d)
        if gait is not None and gait.enabled:
            ControllerCommand.of(gait_manager_commands(obs, dynamics, gait), obs.q, obs.v)
        t1 = clock()
        commands = stack.commands(obs)
        t2 = clock()
        native = native_observation(obs)
        for controller in stack.controllers.values():
            controller.compute(native, stack.kinematics)
        t3 = clock()
        for way, spent in zip(WAYS, (t1 - t0, t2 - t1, t3 - t2), strict=True):
            times[way].append(spent * 1e6)
        session.step(commands)
    periods = len(times[WAYS[0]])
    cpu = machine_info()['cpu']
    print(f'{args.scene}: {periods} control periods ({args.duration:g} s) on {cpu}')
    print(f'{"laws of one period":<40} {"median us":>10} {"mean us":>10} {"Python / this":>14}')
    python_median = statistics.median(times[WAYS[0]])
    for way in WAYS:
        median = statistics.median(times[way])
        print(f'{way:<40} {median:10.1f} {statistics.fmean(times[way]):10.1f} '
              f'{python_median / median:14.1f}')


if __name__ == '__main__':
    main()
