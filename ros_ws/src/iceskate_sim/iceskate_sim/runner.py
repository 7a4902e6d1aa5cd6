"""Headless scene runner: ``run_scene <scene> --out DIR``.

Runs a scene in one process without ROS transport: at every control instant t_k it builds the
observation, asks the scene's controllers for their torques (the same law functions the ROS
nodes call), holds their sum over [t_k, t_k+1] (zero-order hold) and advances the hybrid
simulation. It writes into DIR:

* ``metrics.json``: the figures of the run (see ``iceskate_sim.metrics``);
* ``events.json``: every transition (time, from/to mode, event, cause, impulse);
* ``trajectory.npz``: the sampled state (t, q, v, qdd, mode, side, pivot, step, multipliers,
  support forces, CoP, head pose and target, torques by source);
* ``bag/``: the same run as a rosbag2 MCAP bag (unless the scene turns it off), written by a
  forked writer process while the simulation goes on (``BagRecorder(background=True)``).

A run that diverges raises SimulationError after closing the bag; a fall ends the run with
``fell: true`` and the reason in ``failure``.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
import json
import pathlib
import sys
import time

import numpy as np

from iceskate_sim.command import ControllerCommand, HeldCommand
from iceskate_sim.control_stack import ControlStack
from iceskate_sim.errors import SimulationError
from iceskate_sim.hybrid import Transition
from iceskate_sim.metrics import Trajectory, compute_metrics
from iceskate_sim.recording import BagRecorder, Sample
from iceskate_sim.robot import load_robot
from iceskate_sim.scene import Scene, load_scene
from iceskate_sim.simulation import Simulator


def scene_metadata(scene: Scene) -> dict[str, str]:
    """Bag custom_data: scene name, its full parameters, the integrator."""
    return {'scene': scene.name, 'scene_parameters': json.dumps(scene.raw, sort_keys=True),
            'integrator': json.dumps(asdict(scene.simulator.integrator), sort_keys=True)}


def run(scene: Scene, out: pathlib.Path | None, progress: bool = True) -> dict:
    """Run ``scene``; write the outputs into ``out`` (if given) and return the metrics."""
    robot = load_robot()
    sim = Simulator(robot, scene.simulator, scene.initial)
    stack = ControlStack(scene, robot, sim.observation())
    trajectory = Trajectory()
    recorder = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        if scene.record_bag:
            recorder = BagRecorder(out / 'bag', scene_metadata(scene),
                                   robot.urdf_path.read_text(encoding='utf-8'), background=True)
    n_periods = int(round(scene.duration / scene.simulator.control_period))
    bar = _progress(n_periods, scene.name, progress)
    error: SimulationError | None = None
    wall_start = time.perf_counter()
    try:
        for _ in range(n_periods):
            sample = advance_and_sample(sim, scene, stack.commands(sim.observation()))
            trajectory.append(sample, stack.last_psi_d)
            if recorder is not None:
                recorder.write(sample)
            bar.update(1)
            if sim.ended is not None:
                break
    except SimulationError as exc:
        error = exc
    finally:
        bar.close()
        if recorder is not None:
            recorder.close()
    wall = time.perf_counter() - wall_start
    metrics = compute_metrics(scene, sim, trajectory, wall, error)
    if out is not None:
        (out / 'metrics.json').write_text(json.dumps(metrics, indent=2) + '\n')
        (out / 'events.json').write_text(json.dumps(
            [asdict(e) for e in sim.events], indent=1, default=float) + '\n')
        trajectory.save(out / 'trajectory.npz')
    if error is not None:
        raise error
    return metrics


def advance_and_sample(sim: Simulator, scene: Scene,
                       commands: dict[str, ControllerCommand]) -> Sample:
    """Hold the controllers' ``commands`` (and the scene's push, if one acts) over one control
    period, advance, and return the sample of the period's start: the state (after the
    transitions due at that instant), the dynamics under the held commands, the effort of
    every source as its controller reported it (at the state answered) and the push (headless
    runner and ROS lockstep)."""
    t = sim.state.t
    placement = sim.head_placement()
    push = next(((p.frame, np.array(p.force)) for p in scene.pushes if p.active(t)), None)
    sim.advance(HeldCommand.of_controllers(commands.values()), push)
    state = sim.start_state
    efforts = {source: tau for c in commands.values() for source, tau in c.source_efforts.items()}
    if push is not None:
        efforts['push'] = sim.dynamics.push_force(state.contact, state.q, push)
    return Sample(state, sim.start_result, efforts, placement.translation.copy(),
                  placement.rotation.copy(), last_event_before(sim, state.t))


def last_event_before(sim: Simulator, t: float) -> Transition | None:
    """The latest transition at or before time t (None before the first)."""
    for event in reversed(sim.events):
        if event.t <= t:
            return event
    return None


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, name: str, enabled: bool):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm
    return tqdm(total=total, desc=f'scene {name}', unit='period', mininterval=1.0,
                file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Console entry point."""
    parser = argparse.ArgumentParser(prog='run_scene', description=__doc__.split('\n\n')[0])
    parser.add_argument('scene', help='shipped scene name (e.g. skate) or path to a YAML file')
    parser.add_argument('--out', type=pathlib.Path, required=True, help='output directory')
    parser.add_argument('--duration', type=float, help='override the scene duration [s]')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.add_argument('--ros', action='store_true',
                        help='run through the ROS 2 node graph (iceskate_sim.graph)')
    parser.add_argument('--single-process', action='store_true',
                        help='with --ros: all nodes in one process and one executor')
    parser.add_argument('--rt-priority', type=int, default=0, metavar='N',
                        help='with --ros: run the nodes under SCHED_FIFO at priority N (1-99; '
                             'needs root, CAP_SYS_NICE or an rtprio limit; default 0: off)')
    args = parser.parse_args(argv)
    try:
        if not args.ros and (args.single_process or args.rt_priority):
            raise SimulationError('--single-process and --rt-priority need --ros')
        scene = load_scene(args.scene)
        if args.duration is not None:
            if not args.duration > 0:
                raise SimulationError('--duration must be > 0 s')
            from dataclasses import replace
            scene = replace(scene, duration=args.duration)
        if args.ros:
            from iceskate_sim.graph import run_graph
            metrics = run_graph(args.scene, args.out, duration=args.duration,
                                single_process=args.single_process,
                                rt_priority=args.rt_priority)
        else:
            metrics = run(scene, args.out, progress=not args.quiet)
    except SimulationError as exc:
        print(f'run_scene: error: {exc}', file=sys.stderr)
        return 1
    summary = {k: metrics[k] for k in ('scene', 'sim_time_s', 'steps', 'fell', 'failure',
                                       'forward_distance_m', 'real_time_factor')}
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
