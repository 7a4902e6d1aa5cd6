"""``run_scene <scene> --ros --out DIR``: a scene through the ROS 2 graph (what a launch would do).

Starts the simulator and the controller nodes the scene needs (visual_lifting, gait_manager)
as separate processes, each in its own process group, on one DDS domain (see
``ros_environment``) with LOCALHOST discovery and a per-run ROS_LOG_DIR; waits for the
simulator to end the run; stops the controllers with SIGTERM (SIGKILL after a grace period).
DIR then holds what the headless runner writes: metrics.json, events.json, trajectory.npz and
bag/. ``single_process=True`` runs the three nodes in one process on one EventsExecutor instead.
``rt_priority=N`` (``--rt-priority N``) runs the nodes under real-time scheduling (SCHED_FIFO
at priority N, as ``chrt --fifo N`` would; every thread and the bag writer inherit it): the
processes are started from a thread switched to it for that moment (or, in one process, the
run's thread is switched while it runs).

The executables are the installed ones (``<prefix>/lib/<pkg>/<exe>``, as ``ros2 run`` finds
them), else ``python -m <module>`` from the sources. Node logs go to
``$ROS_LOG_DIR/<node>.log`` (printed on failure).
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
from dataclasses import dataclass
import json
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any

from iceskate_bringup.scene import load_scene, node_parameters, scene_path, scene_sources
from iceskate_sim.errors import SimulationError
from iceskate_sim.node_support import write_parameter_file
from iceskate_sim.parameters import flatten
from iceskate_sim.robot import ament_prefixes

GRACE = 5.0  # s between SIGTERM and SIGKILL
CONTROLLER_CLASSES = {'visual_lifting': 'VisualLiftingNode', 'gait_manager': 'GaitManagerNode'}


@dataclass(frozen=True)
class NodeSpec:
    """One node of the graph: package, executable (= node name), module, class, and the
    parameter file of this run (written by ``graph_nodes``)."""

    package: str
    executable: str
    module: str
    node_class: str
    parameter_file: pathlib.Path

    def ros_args(self) -> list[str]:
        """--ros-args: the node's shipped YAML, then this run's parameter file (which wins)."""
        return ['--ros-args', '--params-file', str(config_file(self.package, self.executable)),
                '--params-file', str(self.parameter_file)]


def config_file(package: str, node: str) -> pathlib.Path:
    """The node's YAML: installed share/<pkg>/config, else the source tree."""
    for prefix in ament_prefixes():
        path = prefix / 'share' / package / 'config' / f'{node}.yaml'
        if path.is_file():
            return path
    source = pathlib.Path(__file__).resolve().parents[2] / package / 'config' / f'{node}.yaml'
    if source.is_file():
        return source
    raise SimulationError(f'no config/{node}.yaml of package {package} (is ros_ws built?)')


def command_of(spec: NodeSpec) -> list[str]:
    """How to start a node: the installed executable, else ``python -m``."""
    for prefix in ament_prefixes():
        exe = prefix / 'lib' / spec.package / spec.executable
        if exe.is_file() and os.access(exe, os.X_OK):
            return [str(exe)]
    return [sys.executable, '-m', spec.module]


def graph_nodes(scene_arg: str, out: pathlib.Path, duration: float | None = None,
                **simulator_parameters: Any) -> list[NodeSpec]:
    """The simulator and the controller nodes the scene runs, each with its parameter file
    written into ``out/params/`` (``<node>.yaml``: the scene composed into node parameters;
    reusable to start the nodes by hand)."""
    scene = load_scene(scene_arg)
    controllers = scene_sources(scene)
    folder = out / 'params'
    folder.mkdir(parents=True, exist_ok=True)
    params: dict[str, Any] = {'scene': str(scene_path(scene_arg).resolve()), 'out_dir': str(out)}
    if scene.record_bag:
        params['record_bag'] = str(out / 'bag')
    if duration is not None:
        params['duration'] = float(duration)
    params.update(simulator_parameters)
    if controllers:
        params['controllers'] = list(controllers)
        params |= {f'sources.{node}': list(sources) for node, sources in controllers.items()}
    write_parameter_file(folder / 'simulator.yaml', {'simulator': params})
    specs = [NodeSpec('iceskate_sim', 'simulator', 'iceskate_sim.simulator_node', 'SimulatorNode',
                      folder / 'simulator.yaml')]
    composed = node_parameters(scene)
    for node in sorted(controllers, reverse=True):
        write_parameter_file(folder / f'{node}.yaml', {node: flatten(composed[node])})
        specs.append(NodeSpec(node, node, f'{node}.{node}_node', CONTROLLER_CLASSES[node],
                              folder / f'{node}.yaml'))
    return specs


def ros_environment(domain_id: int | None = None, log_dir: pathlib.Path | None = None
                    ) -> dict[str, str]:
    """This environment plus a domain, LOCALHOST discovery and a ROS_LOG_DIR of the run.

    The domain is ``domain_id``, else $ROS_DOMAIN_ID when set (to watch the run from a shell),
    else one derived from this process id (1..232; runs started side by side do not meet).
    """
    env = dict(os.environ)
    if domain_id is None:
        domain_id = int(env.get('ROS_DOMAIN_ID') or 1 + os.getpid() % 232)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.pop('ROS_LOCALHOST_ONLY', None)
    env['ROS_LOG_DIR'] = str(log_dir or tempfile.mkdtemp(prefix='iceskate-ros-log-'))
    env['PYTHONUNBUFFERED'] = '1'
    return env


def stop(process: subprocess.Popen, grace: float = GRACE) -> int:
    """SIGTERM the process group, SIGKILL it after ``grace`` s; return the exit code."""
    if process.poll() is None:
        try:
            os.killpg(process.pid, signal.SIGTERM)
            return process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return process.wait()


@contextlib.contextmanager
def realtime_scheduling(priority: int) -> Iterator[None]:
    """The calling thread under SCHED_FIFO at ``priority`` (1-99; 0: scheduling unchanged)
    while the block runs, restored afterwards; threads and processes started meanwhile keep it.

    :raises SimulationError: for a priority out of range, or where SCHED_FIFO is not permitted
        (it needs root, CAP_SYS_NICE or an rtprio limit, e.g. in /etc/security/limits.conf).
    """
    if priority == 0:
        yield
        return
    low, high = (os.sched_get_priority_min(os.SCHED_FIFO),
                 os.sched_get_priority_max(os.SCHED_FIFO))
    if not low <= priority <= high:
        raise SimulationError(f'rt_priority must be 0 (off) or {low}..{high}, got {priority}')
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError as exc:
        raise SimulationError(
            f'rt_priority {priority}: real-time scheduling (SCHED_FIFO) is not permitted here '
            f'({exc.strerror}); it needs root, CAP_SYS_NICE or an rtprio limit >= {priority} '
            '(e.g. "@realtime - rtprio 99" in /etc/security/limits.conf)') from None
    try:
        yield
    finally:
        os.sched_setscheduler(0, policy, param)


def start(spec: NodeSpec, env: dict[str, str]) -> subprocess.Popen:
    """Start one node in its own process group, its output in $ROS_LOG_DIR/<node>.log."""
    log = open(pathlib.Path(env['ROS_LOG_DIR']) / f'{spec.executable}.log', 'wb')  # noqa: SIM115
    with log:
        return subprocess.Popen(command_of(spec) + spec.ros_args(), env=env, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)


def run_graph(scene_arg: str, out: pathlib.Path, *, duration: float | None = None,
              single_process: bool = False, domain_id: int | None = None,
              timeout: float | None = None, rt_priority: int = 0,
              **simulator_parameters: Any) -> dict[str, Any]:
    """Run a scene through the ROS graph; return its metrics (also in ``out/metrics.json``).

    :param timeout: wall-clock limit of the whole run [s] (None: none).
    :param rt_priority: SCHED_FIFO priority of the nodes (0: the default scheduling).
    :param simulator_parameters: extra simulator parameters (e.g. control_timeout=2.0).
    :raises SimulationError: when the simulator fails; the message holds its error.
    """
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    started = time.time()
    specs = graph_nodes(scene_arg, out, duration, **simulator_parameters)
    env = ros_environment(domain_id)
    print(f'graph: domain {env["ROS_DOMAIN_ID"]}, logs in {env["ROS_LOG_DIR"]}', file=sys.stderr)
    if single_process:
        with realtime_scheduling(rt_priority):
            code = run_single_process(specs, env, timeout)
    else:
        with realtime_scheduling(rt_priority):
            processes = [start(spec, env) for spec in specs]
        try:
            why = _wait(processes, specs, timeout,
                        float(simulator_parameters.get('control_timeout', 5.0)) + GRACE)
        finally:
            codes = [stop(p) for p in reversed(processes)]
        code = codes[-1]
        if why:
            _raise(out, env, why, started)
    if code != 0:
        _raise(out, env, f'the simulator exited with {code}', started)
    _write_summary(out)
    return json.loads((out / 'metrics.json').read_text())


def _write_summary(out: pathlib.Path, since: float | None = None) -> None:
    """summary.png from the files the simulator wrote; none if it wrote no trajectory (since
    ``since``, a time.time() before the run: a failed run may have written nothing)."""
    trajectory = out / 'trajectory.npz'
    if trajectory.is_file() and (since is None or trajectory.stat().st_mtime >= since - 0.1):
        from iceskate_analysis.summary import write_summary
        write_summary(out)


def _wait(processes: list[subprocess.Popen], specs: list[NodeSpec], timeout: float | None,
          patience: float) -> str:
    """Wait for the simulator to exit; '' or why it had to be stopped.

    A controller that exits first is the simulator's to report (its control timeout names the
    source); only if the simulator is still up ``patience`` s later is the run stopped here.
    """
    start_time, dead_since = time.monotonic(), None
    while processes[0].poll() is None:
        now = time.monotonic()
        if timeout is not None and now - start_time > timeout:
            return f'the run took longer than {timeout} s (stopped)'
        dead = [s.executable for p, s in zip(processes[1:], specs[1:], strict=True)
                if p.poll() is not None]
        dead_since = (dead_since or now) if dead else None
        if dead and now - dead_since > patience:
            return f'node(s) {dead} exited and the simulator did not end the run (stopped)'
        time.sleep(0.05)
    return ''


def _raise(out: pathlib.Path, env: dict[str, str], what: str, started: float) -> None:
    with contextlib.suppress(SimulationError):  # the picture of the failed run, if it has one
        _write_summary(out, started)
    metrics = out / 'metrics.json'
    failure = json.loads(metrics.read_text()).get('failure') if metrics.is_file() else None
    log = pathlib.Path(env['ROS_LOG_DIR']) / 'simulator.log'
    tail = log.read_text(errors='replace')[-2000:] if log.is_file() else ''
    raise SimulationError(f'{what}: {failure or "no metrics"}\n--- {log} (end) ---\n{tail}')


def run_single_process(specs: list[NodeSpec], env: dict[str, str],
                       timeout: float | None = None) -> int:
    """All nodes in this process on one EventsExecutor; return the simulator's exit code."""
    import importlib

    import rclpy
    from rclpy.experimental import EventsExecutor

    from iceskate_sim.node_support import ConfigError, spin_until
    keys = ('ROS_LOG_DIR', 'ROS_AUTOMATIC_DISCOVERY_RANGE')
    saved = {key: os.environ.get(key) for key in keys}
    os.environ.update({key: env[key] for key in keys})
    context = rclpy.Context()
    nodes: list[Any] = []
    try:
        rclpy.init(context=context, domain_id=int(env['ROS_DOMAIN_ID']))
        for spec in specs:
            cls = getattr(importlib.import_module(spec.module), spec.node_class)
            try:
                nodes.append(cls(context=context, cli_args=spec.ros_args()))
            except ConfigError as exc:
                raise SimulationError(f'node {spec.executable}: {exc}') from None
        executor = EventsExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        deadline = time.monotonic() + (timeout if timeout is not None else float('inf'))
        spin_until(executor, lambda: nodes[0].finished or time.monotonic() > deadline,
                   context, period=0.05)
        if not nodes[0].finished:
            nodes[0].close()
            return 1
        return nodes[0].exit_code
    finally:
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
