"""Headless scene runner: ``run_scene <scene> --out DIR``.

Runs a scene in one process without ROS transport: at every control instant t_k it gives the
controllers (``ControlStack``: the same law functions the ROS nodes call) the observation of
the session, and the session holds their commands over [t_k, t_k+1] (zero-order hold) and
advances the hybrid simulation (``iceskate_sim.session.Session``, the loop the simulator node
runs too). It writes into DIR:

* ``metrics.json``: the figures of the run (see ``iceskate_sim.metrics``);
* ``events.json``: every transition (time, from/to mode, event, cause, impulse);
* ``trajectory.npz``: the sampled state (t, q, v, qdd, mode, side, pivot, step, multipliers,
  support forces, CoP, head pose and target, torques by source);
* ``bag/``: the same run as a rosbag2 MCAP bag (unless the scene turns it off), written by a
  forked writer process while the simulation goes on;
* ``summary.png``: head height and pitch against their targets, gait mode, shoulder angles and
  forward speed over time.

A run that diverges stops with its error after the files are written; a fall ends the run with
``fell: true`` and the reason in ``failure``.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
import pathlib
import sys
from typing import Any

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.scene import Scene
from iceskate_sim.session import Session


def run(scene: Scene, out: pathlib.Path | None, progress: bool = True) -> dict[str, Any]:
    """Run ``scene``; write the outputs into ``out`` (if given) and return the metrics.

    :raises SimulationError: when the physics failed (after the outputs are written).
    """
    bag = out / 'bag' if out is not None and scene.record_bag else None
    session = Session(scene, out, bag)
    stack = ControlStack(scene, session.robot, session.observation())
    bar = _progress(session.n_periods, scene.name, progress)
    try:
        while not session.done:
            session.step(stack.commands(session.observation()))
            session.flush()
            bar.update(1)
    finally:
        bar.close()
        metrics = session.finish()
    if out is not None and len(session.trajectory):  # also after a fall or a physics error
        from iceskate_analysis.summary import write_summary
        write_summary(out)
    if session.error is not None:
        raise session.error
    return metrics


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, name: str, enabled: bool) -> Any:
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
    parser.add_argument('--engine', choices=('python', 'native'),
                        help="where eq. (7) is solved (default: the scene's engine, else "
                             "'python')")
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.add_argument('--ros', action='store_true',
                        help='run through the ROS 2 node graph (iceskate_bringup.graph)')
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
            scene = replace(scene, duration=args.duration)
        if args.engine is not None:
            scene = replace(scene, simulator=replace(scene.simulator, engine=args.engine))
        if args.ros:
            from iceskate_bringup.graph import run_graph
            extra = {'engine': args.engine} if args.engine is not None else {}
            metrics = run_graph(args.scene, args.out, duration=args.duration,
                                single_process=args.single_process,
                                rt_priority=args.rt_priority, **extra)
        else:
            metrics = run(scene, args.out, progress=not args.quiet)
    except SimulationError as exc:
        print(f'run_scene: error: {exc}', file=sys.stderr)
        _print_outputs(args.out)
        return 1
    summary = {k: metrics[k] for k in ('scene', 'sim_time_s', 'steps', 'fell', 'failure',
                                       'forward_distance_m', 'real_time_factor')}
    print(json.dumps(summary, indent=2))
    _print_outputs(args.out)
    return 0


OUTPUTS = ('metrics.json', 'events.json', 'trajectory.npz', 'bag/', 'summary.png')


def _print_outputs(out: pathlib.Path) -> None:
    """Where to look, after the JSON (on stderr: stdout stays the JSON alone)."""
    present = [name for name in OUTPUTS if (out / name.rstrip('/')).exists()]
    if present:
        sys.stdout.flush()  # the JSON first, also when stdout is a pipe
        print(f'outputs in {out}: {", ".join(present)}', file=sys.stderr)


if __name__ == '__main__':
    sys.exit(main())
