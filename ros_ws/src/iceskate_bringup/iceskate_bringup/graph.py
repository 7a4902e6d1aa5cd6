"""``run_scene <scene> --ros --out DIR``: a scene through the ROS 2 graph (what a launch would do).

``run_graph`` starts the simulator and the controller nodes the scene needs as separate
processes (``graph_nodes``, ``start``), or on one executor (``run_single_process``); signals,
the nodes' lifetime, logs and real-time scheduling: docs/usage.md, "Through ROS 2".
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
from dataclasses import dataclass
import json
import os
import pathlib
import secrets
import signal
import subprocess
import tempfile
import time
from typing import Any

import yaml

from iceskate_bringup.controllers import kind_of
from iceskate_bringup.scene import load_scene, node_parameters, scene_sources
from iceskate_bringup.watch import Watch, live_view
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.installed import share_path
from iceskate_sim.model.robot import load_robot
from iceskate_sim.ros.loopback import PROFILE_VARIABLES, loopback_dds
from iceskate_sim.ros.node_support import write_parameter_file
from iceskate_sim.run.session import (
    LOCK_FD_ENV,
    prepare_output,
    release_output,
    start_simulator,
)
from iceskate_sim.shutdown import StopRequest, die_with_parent, process_alive, say

GRACE = 5.0  # s between SIGTERM and SIGKILL
STOP_GRACE = 30.0  # s the simulator has to end a run it was signalled to end (bag, outputs)


@dataclass(frozen=True)
class NodeSpec:
    """One node of the graph: package, executable, module, class, the parameter file of this
    run (written by ``graph_nodes``) and the node's name (``name``; '': the executable's)."""

    package: str
    executable: str
    module: str
    node_class: str
    parameter_file: pathlib.Path
    name: str = ''

    @property
    def node(self) -> str:
        """The node's name (its log is ``<node>.log``)."""
        return self.name or self.executable

    def ros_args(self) -> list[str]:
        """--ros-args: the node's shipped YAML, then this run's parameter file (which wins)."""
        rename = ['-r', f'__node:={self.name}'] if self.name else []
        return ['--ros-args', *rename, '--params-file',
                str(config_file(self.package, self.executable)),
                '--params-file', str(self.parameter_file)]


def config_file(package: str, node: str) -> pathlib.Path:
    """The node's shipped YAML, ``share/<package>/config/<node>.yaml``."""
    path = share_path(package, 'config', f'{node}.yaml')
    if not path.is_file():
        raise SimulationError(f'package {package} installs no config/{node}.yaml')
    return path


def command_of(spec: NodeSpec) -> list[str]:
    """How to start a node: the executable its package installs (``lib/<package>``)."""
    return [str(share_path(spec.package).parents[1] / 'lib' / spec.package / spec.executable)]


def graph_nodes(scene_arg: str, out: pathlib.Path, duration: float | None = None,
                overrides: dict[str, Any] | None = None,
                **simulator_parameters: Any) -> list[NodeSpec]:
    """The simulator and the controller nodes the scene runs, each with its parameter file
    written into ``out/params/`` (``<node>.yaml``: the scene composed into node parameters;
    reusable to start the nodes by hand), and the scene the simulator reads, ``scene.yaml``
    (its base merged in, ``overrides`` set: dotted key -> value). Every node gets the run's
    token (``run_token``, new for each call): the simulator takes commands only from nodes
    that carry it."""
    scene = load_scene(scene_arg, overrides)
    token = secrets.token_hex(16)
    controllers = scene_sources(scene)
    folder = out / 'params'
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'scene.yaml').write_text(yaml.safe_dump(scene.raw, sort_keys=False),
                                       encoding='utf-8')
    params: dict[str, Any] = {'scene': str((folder / 'scene.yaml').resolve()),
                              'out_dir': str(out), 'run_token': token}
    if scene.record_bag:
        params['record_bag'] = str(out / 'bag')
    if duration is not None:
        params['duration'] = float(duration)
    params.update(simulator_parameters)
    if controllers:
        params['controllers'] = list(controllers)
        params |= {f'sources.{node}': list(sources) for node, sources in controllers.items()}
    write_parameter_file(folder / 'simulator.yaml', {'simulator': params})
    specs = [NodeSpec('iceskate_sim', 'simulator', 'iceskate_sim.ros.simulator_node',
                      'SimulatorNode', folder / 'simulator.yaml')]
    composed = node_parameters(scene)
    for node in sorted(controllers, reverse=True):
        kind = kind_of(node, scene.inputs[node])
        write_parameter_file(folder / f'{node}.yaml',
                             {node: kind.ros_parameters(composed[node]) | {'run_token': token}})
        n = kind.node
        specs.append(NodeSpec(n.package, n.executable, n.module, n.node_class,
                              folder / f'{node}.yaml', node if n.renamed else ''))
    return specs


def ros_environment(domain_id: int | None = None, log_dir: pathlib.Path | None = None
                    ) -> dict[str, str]:
    """This environment plus DDS on loopback, a ROS_LOG_DIR of the run and a domain:
    ``domain_id``, else $ROS_DOMAIN_ID when set, else one derived from this process id (1..232;
    runs started side by side do not meet)."""
    env = dict(os.environ)
    if domain_id is None:
        domain_id = int(env.get('ROS_DOMAIN_ID') or 1 + os.getpid() % 232)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    loopback_dds(env)
    env['ROS_LOG_DIR'] = str(log_dir or tempfile.mkdtemp(prefix='iceskate-ros-log-'))
    env['PYTHONUNBUFFERED'] = '1'
    return env


def stop(process: subprocess.Popen, grace: float = GRACE, signum: int = signal.SIGTERM
         ) -> int:
    """Send ``signum`` (SIGTERM) to the process group, SIGKILL it after ``grace`` s; then wait
    (``grace`` s more) for what is left of the group (a simulator's bag writer finishing the
    bag), SIGKILL it after that; return the process's exit code."""
    if process.poll() is None:
        try:
            os.killpg(process.pid, signum)
            process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    code = process.wait()
    deadline = time.monotonic() + grace
    while _group_alive(process.pid):
        if time.monotonic() > deadline:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
            break
        time.sleep(0.02)
    return code


def _group_alive(pgid: int) -> bool:
    """Whether a process of group ``pgid`` is still running (zombies do not count)."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    for entry in pathlib.Path('/proc').iterdir():  # members may be zombies awaiting their reaper
        with contextlib.suppress(OSError, ValueError):
            if os.getpgid(int(entry.name)) == pgid and process_alive(int(entry.name)):
                return True
    return False


@contextlib.contextmanager
def realtime_scheduling(priority: int) -> Iterator[None]:
    """The calling thread under SCHED_FIFO at ``priority`` (1-99; 0: scheduling unchanged)
    while the block runs, restored afterwards; threads and processes started meanwhile keep it.

    :raises InputRefused: for a priority out of range, or where SCHED_FIFO is not permitted
        (it needs root, CAP_SYS_NICE or an rtprio limit, e.g. in /etc/security/limits.conf).
    """
    if priority == 0:
        yield
        return
    low, high = (os.sched_get_priority_min(os.SCHED_FIFO),
                 os.sched_get_priority_max(os.SCHED_FIFO))
    if not low <= priority <= high:
        raise InputRefused(f'rt_priority must be 0 (off) or {low}..{high}, got {priority}')
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError as exc:
        raise InputRefused(
            f'rt_priority {priority}: real-time scheduling (SCHED_FIFO) is not permitted here '
            f'({exc.strerror}); it needs root, CAP_SYS_NICE or an rtprio limit >= {priority} '
            '(e.g. "@realtime - rtprio 99" in /etc/security/limits.conf)') from None
    try:
        yield
    finally:
        os.sched_setscheduler(0, policy, param)


def start(spec: NodeSpec, env: dict[str, str], lock: int | None = None) -> subprocess.Popen:
    """Start one node in its own process group, its output in $ROS_LOG_DIR/<node>.log; ``lock``:
    the output folder's lock descriptor, handed to it. The node gets SIGTERM when this process
    ends, even by SIGKILL (``die_with_parent``)."""
    if lock is not None:
        env = {**env, LOCK_FD_ENV: str(lock)}
    log = open(pathlib.Path(env['ROS_LOG_DIR']) / f'{spec.node}.log', 'wb')  # noqa: SIM115
    parent = os.getpid()
    with log:
        try:
            return subprocess.Popen(command_of(spec) + spec.ros_args(), env=env, stdout=log,
                                    stderr=subprocess.STDOUT, start_new_session=True,
                                    pass_fds=() if lock is None else (lock,),
                                    preexec_fn=lambda: die_with_parent(signal.SIGTERM, parent))
        except OSError as exc:  # e.g. a broken install: the executable cannot be run
            raise SimulationError(f'node {spec.node} could not be started: '
                                  f'{exc.strerror or exc}') from None


def run_graph(scene_arg: str, out: pathlib.Path, *, duration: float | None = None,
              single_process: bool = False, domain_id: int | None = None,
              timeout: float | None = None, rt_priority: int = 0,
              stop: StopRequest | None = None, overrides: dict[str, Any] | None = None,
              watch: Watch | None = None, **simulator_parameters: Any) -> dict[str, Any]:
    """Run a scene (with ``overrides``: dotted key -> value) through the ROS graph; return its
    metrics (also in ``out/metrics.json``). A signal (``stop``) is passed on to the simulator,
    which ends the run cleanly; then the controllers are stopped (docs/usage.md, "Through ROS 2").

    :param timeout: wall-clock limit of the whole run [s] (None: none).
    :param rt_priority: SCHED_FIFO priority of the nodes (0: the default scheduling).
    :param stop: the caller's StopRequest (None: one is installed for the call).
    :param watch: show the run live (the simulator keeps the page's pace and pause).
    :param simulator_parameters: extra simulator parameters (e.g. control_timeout=2.0).
    :raises RunInterrupted: after a signal (the outputs are written).
    :raises SimulationError: when the run failed (the simulator's error, or why a node had to
        be stopped).
    """
    out = out.resolve()
    with contextlib.ExitStack() as stack:
        if stop is None:
            stop = stack.enter_context(StopRequest())
        scene = load_scene(scene_arg, overrides)
        robot = load_robot()
        start_simulator(scene, robot)  # refuses an initial state the run cannot start from
        lock = prepare_output(out, out / 'bag' if scene.record_bag else None)
        stack.callback(release_output, out)
        if watch is not None:  # the live view resumes it once connected
            simulator_parameters |= {'pace': watch.pace, 'start_paused': True}
        specs = graph_nodes(scene_arg, out, duration, overrides, **simulator_parameters)
        env = ros_environment(domain_id)
        say(f'graph: domain {env["ROS_DOMAIN_ID"]}, logs in {env["ROS_LOG_DIR"]}')
        if (live := live_view(watch, robot, scene.name, stack)) is not None:
            from iceskate_viewer.live_node import watching
            stack.enter_context(process_environment(env))
            controllers = sum(spec.node != 'simulator' for spec in specs)
            stack.enter_context(watching(live, int(env['ROS_DOMAIN_ID']), controllers))
        why, early = '', {}
        if single_process:
            with realtime_scheduling(rt_priority):
                code = run_single_process(specs, env, timeout, stop)
        else:
            processes: list[subprocess.Popen] = []
            try:
                with realtime_scheduling(rt_priority):
                    for spec in specs:
                        processes.append(start(spec, env, lock if spec.node == 'simulator'
                                               else None))
                patience = float(simulator_parameters.get('control_timeout', 5.0)) + GRACE
                why = _wait(processes, specs, timeout, patience, stop)
                early = {s.node: p.returncode for p, s in zip(processes, specs, strict=True)
                         if s.node != 'simulator' and p.poll() is not None}
            finally:
                codes = stop_graph(processes, stop.signum)
            code = codes[0] if codes else None
        metrics = _read_metrics(out / 'metrics.json')
        if metrics is not None:
            _report_rejected(metrics, env)
        if stop.requested and (metrics is None or metrics.get('interrupted')):
            error = stop.error(metrics.get('sim_time_s') if metrics else None)
            if metrics is None:
                _write_metrics(out, scene.name, str(error), interrupted=True)
            raise error
        if why or code != 0 or metrics is None:
            _fail(out, env, scene.name, why, code, early, metrics)
        _write_summary(out)
        return metrics


def stop_graph(processes: list[subprocess.Popen], signum: int | None = None) -> list[int]:
    """Stop the graph's processes; return their exit codes in order. The simulator (first) gets
    ``signum`` (None: SIGTERM) and ``STOP_GRACE`` s to end its run; the controllers SIGTERM."""
    codes = [stop(p, STOP_GRACE, signum or signal.SIGTERM) for p in processes[:1]]
    return codes + [stop(p) for p in processes[1:]]


def _read_metrics(path: pathlib.Path) -> dict[str, Any] | None:
    """The metrics the run wrote (None: it wrote none; the folder held none before it)."""
    try:
        metrics = json.loads(path.read_text(encoding='utf-8'))
    except (OSError, ValueError):
        return None
    return metrics if isinstance(metrics, dict) else None


def _write_metrics(out: pathlib.Path, scene: str, failure: str, interrupted: bool) -> None:
    """metrics.json of a run whose simulator wrote none (it was killed or never started)."""
    metrics = {'scene': scene, 'sim_time_s': None, 'steps': None,
               'end': 'interrupted' if interrupted else 'failed', 'fell': False,
               'failure': failure, 'interrupted': interrupted}
    with contextlib.suppress(OSError):
        (out / 'metrics.json').write_text(json.dumps(metrics, indent=2) + '\n')


def exit_text(code: int | None) -> str:
    """'exited with 1', 'was killed by SIGKILL', ... of a process's exit code."""
    if code is None:
        return 'did not start'
    if code < 0:
        try:
            return f'was killed by {signal.Signals(-code).name}'
        except ValueError:
            return f'was killed by signal {-code}'
    return f'exited with {code}'


def _node_error(env: dict[str, str], node: str) -> str:
    """The one-line error a node printed before exiting ('' if none)."""
    log = pathlib.Path(env['ROS_LOG_DIR']) / f'{node}.log'
    text = log.read_text(errors='replace') if log.is_file() else ''
    lines = [line for line in text.splitlines() if line.startswith(f'{node}: error: ')]
    return lines[-1][len(f'{node}: error: '):] if lines else ''


def _fail(out: pathlib.Path, env: dict[str, str], scene: str, why: str, code: int | None,
          early: dict[str, int], metrics: dict[str, Any] | None) -> None:
    """Raise the SimulationError of a failed run: this run's reason, in one line where the
    simulator gave one (the end of its log otherwise)."""
    if metrics is not None:
        with contextlib.suppress(SimulationError):  # the picture of the failed run
            _write_summary(out)
    what = why or f'the simulator {exit_text(code)}'
    if early:
        what += '; ' + ', '.join(f'node {n} {exit_text(c)} first' for n, c in early.items())
    reason = (metrics or {}).get('failure') or _node_error(env, 'simulator')
    if not reason and code is not None and code < 0:
        reason = 'it wrote no metrics (the bag keeps what was recorded)'
    elif not reason:  # no outputs and no error line: a crash; its log says what happened
        log = pathlib.Path(env['ROS_LOG_DIR']) / 'simulator.log'
        tail = log.read_text(errors='replace')[-2000:] if log.is_file() else ''
        reason = f'no metrics\n--- {log} (end) ---\n{tail}'
    if metrics is None:
        _write_metrics(out, scene, f'{what}: {reason.splitlines()[0]}',
                       interrupted=code is not None and code < 0)
    raise SimulationError(f'{what}: {reason}')


def _report_rejected(metrics: dict[str, Any], env: dict[str, str]) -> None:
    """The run's rejected commands on stderr: how many, per reason, the first few."""
    rejected = metrics.get('rejected_commands') or {}
    if not rejected.get('count'):
        return
    log = pathlib.Path(env['ROS_LOG_DIR']) / 'simulator.log'
    lines = [f'graph: {rejected["count"]} command(s) rejected (each is in {log}):']
    lines += [f'  {n} x {reason}' for reason, n in rejected.get('by_reason', {}).items()]
    lines += ['  first: ' + text for text in rejected.get('first', [])]
    say('\n'.join(lines))


def _write_summary(out: pathlib.Path) -> None:
    """summary.png from the files the simulator wrote (none without a trajectory)."""
    if (out / 'trajectory.npz').is_file():
        from iceskate_analysis.summary import write_summary
        write_summary(out)


def _wait(processes: list[subprocess.Popen], specs: list[NodeSpec], timeout: float | None,
          patience: float, stop: StopRequest) -> str:
    """Wait for the simulator to exit; '' or why it had to be stopped ('' for a signal). A
    controller that exits first is the simulator's to report; only if the simulator is still up
    ``patience`` s later is the run stopped here."""
    start_time, dead_since = time.monotonic(), None
    while processes[0].poll() is None and not stop.requested:
        now = time.monotonic()
        if timeout is not None and now - start_time > timeout:
            return f'the run took longer than {timeout} s (stopped)'
        dead = [s.node for p, s in zip(processes[1:], specs[1:], strict=True)
                if p.poll() is not None]
        dead_since = (dead_since or now) if dead else None
        if dead and now - dead_since > patience:
            return f'node(s) {dead} exited and the simulator did not end the run (stopped)'
        time.sleep(0.05)
    return ''


def run_single_process(specs: list[NodeSpec], env: dict[str, str], timeout: float | None,
                       stop: StopRequest) -> int:
    """All nodes in this process on one EventsExecutor; return the simulator's exit code
    (after a signal of ``stop``: the run ended cleanly, 128 + its number)."""
    import importlib

    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.signals import SignalHandlerOptions

    from iceskate_sim.ros.node_support import ConfigError, spin_until
    context = rclpy.Context()
    nodes: list[Any] = []
    try:
        with process_environment(env):
            rclpy.init(context=context, domain_id=int(env['ROS_DOMAIN_ID']),
                       signal_handler_options=SignalHandlerOptions.NO)  # ``stop`` has them
            for spec in specs:
                cls = getattr(importlib.import_module(spec.module), spec.node_class)
                try:
                    nodes.append(cls(context=context, cli_args=spec.ros_args()))
                except ConfigError as exc:
                    raise SimulationError(f'node {spec.node}: {exc}') from None
        executor = EventsExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        deadline = time.monotonic() + (timeout if timeout is not None else float('inf'))
        spin_until(executor, lambda: (nodes[0].finished or stop.signum is not None
                                      or time.monotonic() > deadline), context, period=0.05)
        if not nodes[0].finished:
            nodes[0].close(stop.signum)
        return nodes[0].exit_code
    finally:
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()


@contextlib.contextmanager
def process_environment(env: dict[str, str]) -> Iterator[None]:
    """This process's environment with the ROS log folder and the DDS settings of ``env``
    (``ros_environment``) while the block runs: nodes created in it live by them."""
    keys = ('ROS_LOG_DIR', 'ROS_AUTOMATIC_DISCOVERY_RANGE', *PROFILE_VARIABLES)
    saved = {key: os.environ.get(key) for key in keys}
    os.environ.update({key: env[key] for key in keys})
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
