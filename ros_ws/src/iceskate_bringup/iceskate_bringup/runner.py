"""Headless scene runner: ``run_scene <scene> --out DIR``.

Runs a scene in one process without ROS transport (``run``: ``ControlStack``'s laws and the
``Session`` loop the simulator node runs too) and writes metrics.json, events.json,
trajectory.npz, bag/ and summary.png into DIR; how a run ends (a fall, a divergence, a signal)
and what it leaves: docs/usage.md, "Run a scene".
"""

from __future__ import annotations

import argparse
import contextlib
from dataclasses import dataclass, replace
import json
import math
import os
import pathlib
import sys
import time
from typing import TYPE_CHECKING, Any

from iceskate_bringup.watch import Watch, live_view

# light imports only at the top: main() installs its signal handlers before the heavy ones
from iceskate_sim.errors import InputRefused, RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.progress import ProgressBar
from iceskate_sim.shutdown import StopRequest, say
from iceskate_sim.yaml_io import yaml_value

if TYPE_CHECKING:
    from iceskate_analysis.summary_process import SummaryProcess
    from iceskate_sim.run.scene import Scene
    from iceskate_sim.run.session import Session

#: Control periods run per call of ``Session.run_periods`` at the most (one native call, ~20 ms
#: at the shipped settings): a signal is answered, and the progress shown, between two such
#: blocks; the bag writer encodes a block at once (longer blocks: fewer, larger array operations).
BLOCK_PERIODS = 1000
#: Wall time [s] a block is sized to (fewer periods where a period costs more, e.g. a tiny
#: integrator step), so that a signal ends any run within about this long.
BLOCK_SECONDS = 0.2
#: Periods of the first block (then at most ten times the last, as their cost allows).
FIRST_BLOCK = 10


@dataclass(frozen=True)
class Outcome:
    """How ``simulate`` ended: the ``metrics``; the ``error`` of the physics or of a controller
    that ended the run (None: it completed or fell); the ``session``, with the samples
    (``session.trajectory``) and events (``session.sim.events``) in memory."""

    metrics: dict[str, Any]
    error: SimulationError | None
    session: Session


def run(scene: Scene, out: pathlib.Path | None, progress: bool = True,
        stop: StopRequest | None = None, picture: bool = True,
        watch: Watch | None = None, aside: bool = False) -> dict[str, Any]:
    """Run ``scene``; write the outputs into ``out`` (if given) and return the metrics.

    A signal (``stop``; None: one is installed for the call) ends the run between two control
    periods, its outputs written (docs/usage.md, "Run a scene"). ``picture``: draw summary.png;
    ``aside``: in a process forked before the run, which imports matplotlib meanwhile (for a
    process that runs one scene: the picture then costs its drawing only).

    :raises RunInterrupted: after a signal (the outputs are written; no summary.png).
    :raises SimulationError: when the physics failed (after the outputs are written).
    """
    outcome = simulate(scene, out, progress, stop, picture, watch, aside)
    if outcome.error is not None:
        raise outcome.error
    return outcome.metrics


def simulate(scene: Scene, out: pathlib.Path | None, progress: bool = True,
             stop: StopRequest | None = None, picture: bool = True, watch: Watch | None = None,
             aside: bool = False) -> Outcome:
    """``run``, but a failure of the physics, or of a controller written in Python
    (``iceskate_native.ControllerError``: it raised or answered a bad command), is returned
    in the ``Outcome`` beside the metrics (which say where the run stopped) instead of raised.

    :raises RunInterrupted: after a signal (the outputs are written; no summary.png).
    """
    from iceskate_bringup.composition import ControlStack
    from iceskate_native import ControllerError
    from iceskate_sim.run.session import Session
    with contextlib.ExitStack() as signals:
        if stop is None:
            stop = signals.enter_context(StopRequest())
        bag = out / 'bag' if out is not None and scene.record_bag else None
        session = Session(scene, out, bag)  # forks the bag writer (before any thread starts)
        stack = ControlStack(scene, session.robot, session.observation())
        picture = picture and out is not None
        painter: SummaryProcess | None = None
        bar: ProgressBar | None = None
        ended: SimulationError | None = None
        controller_failed = False

        def summary() -> None:
            """summary.png, while the bag writer finishes; also after a fall or a physics
            error, not after a signal, a bug or a failure to write (a full disk)."""
            if not picture:
                return
            from iceskate_analysis.summary import DRAWN_COLUMNS, SUMMARY_NAME, draw_summary
            path = out / SUMMARY_NAME
            if session.metrics['end'] == 'io_error':  # drawn before the bag failed
                path.unlink(missing_ok=True)
            elif (len(session.trajectory) and not isinstance(ended, RunInterrupted)
                    and not crashed):
                staged = path.with_name(f'.{SUMMARY_NAME}')
                try:
                    draw = painter.draw if painter is not None else draw_summary
                    draw(session.trajectory.columns(DRAWN_COLUMNS), session.metrics, staged)
                    os.replace(staged, path)
                except (OSError, SimulationError) as exc:  # SimulationError: its process
                    staged.unlink(missing_ok=True)
                    reason = exc.strerror if isinstance(exc, OSError) else None
                    say(f'run_scene: {path} not written: {reason or exc}')

        crashed = False
        block = FIRST_BLOCK
        live = None
        try:
            if picture and aside:  # forked before any thread starts, like the bag writer
                from iceskate_analysis.summary_process import SummaryProcess
                painter = signals.enter_context(contextlib.closing(SummaryProcess()))
            bar = ProgressBar(session.n_periods, f'scene {scene.name}', 'period', progress)
            live = live_view(watch, session.robot, scene.name, signals)
            while not session.done:
                if stop.requested:
                    ended = stop.error(session.sim.time)
                    break
                started = time.perf_counter()
                bar.update(session.run_periods(stack, block))
                spent = max(time.perf_counter() - started, 1e-6)
                most = BLOCK_PERIODS
                if live is not None and session.latest is not None:
                    live.offer_last(session.latest)
                    live.keep_pace(session.sim.time, stop)
                    most = min(most, live.periods_per_frame(scene.simulator.control_period))
                block = max(1, min(most, 10 * block, int(block * BLOCK_SECONDS / spent)))
        except ControllerError as exc:  # the samples before it are recorded: the run ends here
            ended = SimulationError(str(exc), end='controller_failed')
            controller_failed = True
        except BaseException as exc:  # a bug: the outputs still say where the run stopped
            ended = SimulationError(f'the run stopped on {type(exc).__name__}: {exc}')
            crashed = True
            raise
        finally:
            if bar is not None:
                bar.close()
            metrics = session.finish(ended, written=summary)
    if isinstance(ended, RunInterrupted):
        raise ended
    return Outcome(metrics, ended if controller_failed else session.error, session)


def _with_arm_swing_ratio(scene: Scene, metrics: dict[str, Any], out: pathlib.Path,
                          stop: StopRequest) -> dict[str, Any]:
    """``metrics`` of the run of ``scene`` with ``arm_swing_ratio`` (None: no ratio, and one
    line says why): ``scene`` run again without the torso-yaw input tau8, headless and without
    outputs; also written into ``out/metrics.json``."""
    from gait_manager.parameters import GaitManagerParameters
    from iceskate_sim.disk import write_atomically
    from iceskate_sim.run.metrics import arm_swing_ratio
    gait = scene.inputs.get('gait_manager')
    enabled = list(GaitManagerParameters.from_dict(gait).enabled) if gait is not None else []
    if 'yaw' not in enabled:
        say(f'run_scene: {scene.name} has no torso-yaw input (gait_manager.enabled lacks yaw): '
            'no arm-swing ratio')
        return metrics
    inputs = {**scene.inputs, 'gait_manager': {
        **scene.inputs['gait_manager'], 'enabled': [s for s in enabled if s != 'yaw']}}
    outcome = simulate(replace(scene, inputs=inputs), None, progress=False, stop=stop,
                       picture=False)
    without, error = outcome.metrics, outcome.error
    ratio = arm_swing_ratio(metrics, without) if error is None else None
    if ratio is None:
        say('run_scene: no arm-swing ratio: '
            + (f'the run without yaw ended {without["end"]} at t={without["sim_time_s"]:.3f} s'
               if error is not None or without['end'] != 'completed' else
               'a run fell, took fewer than 4 steps, or did not swing without yaw'))
    metrics = {**metrics, 'arm_swing_ratio': ratio}
    try:
        write_atomically(out / 'metrics.json', (json.dumps(metrics, indent=2) + '\n').encode())
    except OSError as exc:
        say(f'run_scene: the arm-swing ratio is not in {out / "metrics.json"}: '
            f'{exc.strerror or exc}')
    return metrics


def main(argv: list[str] | None = None) -> int:
    """Console entry point.

    Exit status (``iceskate_sim.exit_codes``): 0 (the run ended: complete or a fall), 2 (refused
    before it started) or 1 (it failed), with one line on stderr saying why; 130, 143 or 129
    after SIGINT, SIGTERM or SIGHUP (the run was ended cleanly: one line on stderr with the time
    it reached and its outputs).
    """
    with StopRequest() as stop:  # first of all: a signal never kills the run half-written
        return _main(argv, stop)


def _main(argv: list[str] | None, stop: StopRequest) -> int:
    parser = argparse.ArgumentParser(prog='run_scene', description=__doc__.split('\n\n')[0])
    parser.add_argument('scene', help='shipped scene name (e.g. skate) or path to a YAML file')
    parser.add_argument('--out', type=pathlib.Path, required=True, help='output directory')
    parser.add_argument('--duration', type=float, help='override the scene duration [s]')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                        help='set a scene key (dotted, e.g. floor.mu=0.01 or '
                             "'inputs.visual_lifting.kp=[30, 290, 1100]'; VALUE in YAML); "
                             'repeatable')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.add_argument('--arm-swing-ratio', action='store_true',
                        help='then run the scene again without the torso-yaw input (headless, '
                             'no outputs) and report the arm-swing ratio in metrics.json')
    parser.add_argument('--ros', action='store_true',
                        help='run through the ROS 2 node graph (iceskate_bringup.graph)')
    parser.add_argument('--single-process', action='store_true',
                        help='with --ros: all nodes in one process and one executor')
    parser.add_argument('--rt-priority', type=int, default=0, metavar='N',
                        help='with --ros: run the nodes under SCHED_FIFO at priority N (1-99; '
                             'needs root, CAP_SYS_NICE or an rtprio limit; default 0: off)')
    parser.add_argument('--view', action='store_true',
                        help='watch the run in 3D in the browser (run_scene prints the address)')
    parser.add_argument('--pace', type=float, metavar='X',
                        help='with --view: simulated seconds per wall second (default 1; 0: as '
                             'fast as it runs; also a control on the page)')
    parser.add_argument('--view-host', metavar='HOST',
                        help='with --view: address the page is served on (default 127.0.0.1: '
                             'this machine only)')
    parser.add_argument('--view-port', type=int, metavar='PORT',
                        help='with --view: port of the page (default 8080; a busy one: the next '
                             'free one; 0: any)')
    args = parser.parse_args(argv)
    from iceskate_bringup.scene import controllers_line, load_scene
    from iceskate_sim.model.robot import load_robot
    from iceskate_sim.run.scene import MAX_DURATION
    from iceskate_sim.run.session import prepare_output, start_simulator
    started = False
    try:
        if not args.ros and (args.single_process or args.rt_priority):
            raise InputRefused('--single-process and --rt-priority need --ros')
        watch = _watch(args)
        overrides = set_options(args.set)
        scene = load_scene(args.scene, overrides)
        if args.duration is not None:
            if not (math.isfinite(args.duration) and 0.0 < args.duration <= MAX_DURATION):
                raise InputRefused(f'--duration must be > 0 and <= {MAX_DURATION:g} s (the '
                                   f"limits of a scene's duration), got {args.duration:g}")
            scene = replace(scene, duration=args.duration)
        start_simulator(scene, load_robot())  # an initial state it cannot start from: refused
        prepare_output(args.out, args.out / 'bag' if scene.record_bag else None)
        started = True  # from here on, what is in --out is this run's
        say(f'run_scene: {controllers_line(scene, args.scene, overrides)}')
        if args.ros:
            from iceskate_bringup.graph import run_graph
            metrics = run_graph(args.scene, args.out, duration=args.duration,
                                single_process=args.single_process,
                                rt_priority=args.rt_priority, stop=stop, overrides=overrides,
                                watch=watch)
        else:
            metrics = run(scene, args.out, progress=not args.quiet, stop=stop, watch=watch,
                          aside=True)
        if args.arm_swing_ratio:
            metrics = _with_arm_swing_ratio(scene, metrics, args.out, stop)
    except RunInterrupted as exc:  # the run was ended cleanly: one line, the shell's code
        say(f'run_scene: {exc}' + (f'; {_outputs(args.out)}' if _outputs(args.out) else ''))
        return exc.exit_code
    except SimulationError as exc:
        code = error_exit('run_scene', exc)
        if started:
            _print_outputs(args.out)
        return code
    summary = {k: metrics.get(k) for k in ('scene', 'sim_time_s', 'steps', 'end', 'failure',
                                           'forward_distance_m', 'head_error_rms', 'arm_swing',
                                           'arm_swing_steady', 'arm_swing_ratio',
                                           'real_time_factor')
               if k in metrics}
    with contextlib.suppress(OSError, ValueError):  # stdout gone (a closed terminal)
        print(json.dumps(summary, indent=2), flush=True)
    _print_outputs(args.out)
    return DONE


def _watch(args: argparse.Namespace) -> Watch | None:
    """The ``Watch`` of ``--view``, ``--pace``, ``--view-host`` and ``--view-port``."""
    given = [name for name in ('pace', 'view_host', 'view_port')
             if getattr(args, name) is not None]
    if not args.view:
        if given:
            raise InputRefused(f'--{given[0].replace("_", "-")} needs --view')
        return None
    from iceskate_viewer.page import check_host, check_port
    check_host(args.view_host or '127.0.0.1')  # refused before anything starts
    pace = 1.0 if args.pace is None else args.pace
    from iceskate_sim.run.pace import MAX_PACE
    if not (math.isfinite(pace) and 0.0 <= pace <= MAX_PACE):
        raise InputRefused(f'--pace must be >= 0 (0: as fast as it runs) and <= '
                           f'{MAX_PACE:g}, got {pace:g}')
    port = 8080 if args.view_port is None else args.view_port
    check_port(port, '--view-port')
    return Watch(pace, args.view_host or '127.0.0.1', port)


def set_options(settings: list[str]) -> dict[str, Any]:
    """Scene key -> value of ``--set KEY=VALUE`` options (VALUE read as YAML)."""
    out = {}
    for setting in settings:
        key, equals, value = setting.partition('=')
        if not equals or not key.strip():
            raise InputRefused(f'--set {setting!r}: give KEY=VALUE (e.g. floor.mu=0.01)')
        out[key.strip()] = yaml_value(value, f'--set {key.strip()}')
    return out


OUTPUTS = ('metrics.json', 'events.json', 'trajectory.npz', 'bag/', 'summary.png')


def _outputs(out: pathlib.Path) -> str:
    """'outputs in DIR: metrics.json, ...' ('' when there are none)."""
    present = [name for name in OUTPUTS if (out / name.rstrip('/')).exists()]
    return f'outputs in {out}: {", ".join(present)}' if present else ''


def _print_outputs(out: pathlib.Path) -> None:
    """Where to look, after the JSON (on stderr: stdout stays the JSON alone)."""
    if text := _outputs(out):
        with contextlib.suppress(OSError, ValueError):
            sys.stdout.flush()  # the JSON first, also when stdout is a pipe
        say(text)


if __name__ == '__main__':
    sys.exit(main())
