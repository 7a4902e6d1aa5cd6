"""What every iceskate node shares: the QoS profiles (``STATE_QOS``, ``LOCKSTEP_READER_QOS``,
``LATCHED_QOS``), typed parameters from a parameter class (``declare_parameters``,
``ConfigError``) and the Jazzy main() (``run_node``). See docs/usage.md, 'Through ROS 2: the
node graph, bags, replay, analysis', and docs/architecture.md, 'Parameters'.
"""

from __future__ import annotations

import array
from collections.abc import Callable
import os
import pathlib
import signal
import sys
import typing
from typing import Any, TypeVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
import yaml

from iceskate_native.parameters import (
    Rules,
    flatten,
    from_mapping,
    leaf_fields,
    optional_inner,
    unflatten,
)
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.exit_codes import error_exit
from iceskate_sim.recording.bag_types import OFFERED_QOS
from iceskate_sim.ros.loopback import loopback_dds
from iceskate_sim.shutdown import STOP_SIGNALS, StopRequest, process_alive
from iceskate_sim.yaml_io import read_yaml

T = TypeVar('T')

STATE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: The lockstep's readers (the controllers' state, the simulator's commands): best effort, so
#: no acknowledgement goes back per message (a reliable writer serves a best-effort reader
#: without them); a message lost is recovered by the simulator's resend of an unanswered state.
LOCKSTEP_READER_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
                                 durability=DurabilityPolicy.VOLATILE)

def _profile(qos: dict[str, Any]) -> QoSProfile:
    """rclpy's profile of a QoS in rosbag2's metadata form (the same policy names)."""
    return QoSProfile(history=HistoryPolicy[qos['history'].upper()], depth=qos['depth'],
                      reliability=ReliabilityPolicy[qos['reliability'].upper()],
                      durability=DurabilityPolicy[qos['durability'].upper()],
                      liveliness=LivelinessPolicy[qos['liveliness'].upper()])


#: /robot_description: latched, as the bag records it (``bag_types.OFFERED_QOS``).
LATCHED_QOS = _profile(OFFERED_QOS['/robot_description'][0])
#: /clock: reliable writers match best-effort readers too (rclpy's TimeSource reads it so).
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class ConfigError(InputRefused):
    """A node parameter (or the scene it names) is unusable: refused before the node runs; the
    message names it."""


def _ros_type(tp: Any) -> Parameter.Type:
    """The ROS parameter type of a parameter-class field type."""
    tp = optional_inner(tp)
    if typing.get_origin(tp) in (tuple, frozenset):
        return Parameter.Type[_ROS_TYPES[typing.get_args(tp)[0]] + '_ARRAY']
    return Parameter.Type[_ROS_TYPES[tp]]


_ROS_TYPES = {bool: 'BOOL', int: 'INTEGER', float: 'DOUBLE', str: 'STRING'}


def _descriptor(name: str, ros_type: Parameter.Type, rules: Rules, optional: bool
                ) -> ParameterDescriptor:
    """The descriptor of a field: description with unit, range and choices, the type (no ROS
    range for an optional number: its NaN means unset; the rules still check it)."""
    text = rules.description + (f' [{rules.unit}]' if rules.unit else '')
    if rules.choices:
        text += f'; one of {list(rules.choices)}'
    descriptor = ParameterDescriptor(name=name, type=ros_type.value, description=text)
    if rules.low is not None or rules.high is not None:
        descriptor.additional_constraints = f'range {rules.bounds_text()}'
    if not optional and (rules.low is not None or rules.high is not None):
        low = rules.low if rules.low is not None else -sys.float_info.max
        high = rules.high if rules.high is not None else sys.float_info.max
        if ros_type == Parameter.Type.DOUBLE:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(low), to_value=float(high), step=0.0)]
        elif ros_type == Parameter.Type.INTEGER:
            descriptor.integer_range = [IntegerRange(
                from_value=int(max(low, -2**63)), to_value=int(min(high, 2**63 - 1)), step=0)]
    return descriptor


def declare_parameters(node: Node, cls: type[T], error: type[Exception],
                       on_change: Callable[[T], None] | None = None) -> T:
    """Declare every field of parameter class ``cls`` as a typed ROS parameter (dotted names
    for nested blocks; description, unit and range from its ``setting``; an unset optional
    number is NaN) and return the parameter object built from the node's values.

    ``ros2 param set`` then goes through the class's own rules: a bad value is refused with
    their reason, a good one gives ``on_change`` the new object.

    :raises ConfigError: for a value the rules refuse (naming the parameter).
    """
    defaults = flatten(cls())
    for name, (tp, rules, _) in leaf_fields(cls).items():
        ros_type = _ros_type(tp)
        descriptor = _descriptor(name, ros_type, rules, optional_inner(tp) is not tp)
        value = defaults[name]
        try:
            node.declare_parameter(name, value if value != [] else ros_type, descriptor)
        except ParameterException as exc:
            raise ConfigError(f'parameter {name!r}: {exc}') from None

    def current(changes: dict[str, Any]) -> T:
        values = {name: _python_value(node.get_parameter(name).value)
                  for name in defaults} | changes
        return from_mapping(cls, unflatten(cls, values), error)

    try:
        params = current({})
    except error as exc:
        raise ConfigError(f'parameters of {node.get_name()!r}: {exc}') from None

    def validate(changes: list[Parameter]) -> SetParametersResult:
        ours = {p.name: _python_value(p.value) for p in changes if p.name in defaults}
        if not ours:
            return SetParametersResult(successful=True)
        try:
            new = current(ours)
        except error as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if on_change is not None:
            on_change(new)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(validate)
    return params


def _python_value(value: Any) -> Any:
    """A parameter value as the parameter classes take it (arrays as lists, unset: [])."""
    if value is None:
        return []
    if isinstance(value, (array.array, tuple)):
        return list(value)
    return value


def write_parameter_file(path: pathlib.Path, nodes: dict[str, dict[str, Any]]) -> None:
    """Write a ROS 2 parameter file: ``{node: {ros__parameters: {name: value}}}`` (dotted
    names nested as ROS expects, NaN as .nan), readable by the user alone."""
    def nested(flat: dict[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, value in flat.items():
            *heads, leaf = name.split('.')
            where = out
            for head in heads:
                where = where.setdefault(head, {})
            where[leaf] = value
        return out

    document = {node: {'ros__parameters': nested(values)} for node, values in nodes.items()}
    text = yaml.safe_dump(document, sort_keys=False, default_flow_style=None)
    # readable by the user alone (a run's files hold its run token), never through a link
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, 'w', encoding='utf-8') as stream:
        stream.write(text)


def check_unknown(node: Node) -> None:
    """Refuse parameter overrides (params file, -p) the node never declared (typos)."""
    overrides = getattr(node, '_parameter_overrides', {})  # rclpy keeps them there
    unknown = sorted(n for n in overrides
                     if not node.has_parameter(n) and not n.startswith('qos_overrides.'))
    if unknown:
        known = sorted(node._parameters)
        raise ConfigError(f'unknown parameter {unknown[0]!r} for node {node.get_name()!r}; '
                          f'its parameters: {known}')


def spin_until(executor: Any, done: Callable[[], bool], context: Any = None,
               period: float = 0.1) -> None:
    """spin_once in a loop until ``done()`` or the context shuts down (SIGTERM)."""
    while not done() and (context.ok() if context is not None else rclpy.ok()):
        executor.spin_once(timeout_sec=period)


def usage(package: str, name: str, about: str, parameters: type | None) -> str:
    """The ``--help`` text of executable ``name`` of ROS package ``package``: how to call it
    (here, and with ROS 2's CLI), what it does, its ROS parameters (from the parameter class:
    default, unit, range, description)."""
    options = '[-h] [--ros-args [-p NAME:=VALUE]... [--params-file FILE]]'
    lines = [f'usage: {name} {options}', f'   or: ros2 run {package} {name} {options}',
             '       (with ROS 2 Jazzy installed and ros_ws built into an overlay)', '',
             about.strip()]
    if parameters is not None:
        lines += ['', 'ROS parameters (-p NAME:=VALUE or a --params-file; with ROS 2 installed, '
                  'ros2 param describe shows them too):']
        for key, (_, rules, default) in leaf_fields(parameters).items():
            extra = ', '.join(x for x in (rules.unit, rules.bounds_text()) if x)
            lines.append(f'  {key} = {default!r}{f" ({extra})" if extra else ""}: '
                         f'{rules.description}')
    return '\n'.join(lines)


def init_ros(args: list[str] | None) -> None:
    """``rclpy.init`` with ``args`` (None: the command line), without rclpy's signal handlers
    (a ``StopRequest`` has them).

    :raises InputRefused: for ``--ros-args`` rcl refuses (a malformed ``-p``, a parameter file
        it cannot parse, an unknown argument).
    """
    from rclpy.signals import SignalHandlerOptions
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as exc:  # RCLError, UnknownROSArgsError
        raise InputRefused(f'{type(exc).__name__}: {exc}') from None


def run_node(make: Callable[..., Node], package: str, name: str, args: list[str] | None = None,
             about: str = '', parameters: type | None = None) -> int:
    """The Jazzy main(): init, make the node, spin until it is finished or stopped.

    ``-h``/``--help`` before ``--ros-args`` prints ``usage(package, name, about, parameters)``
    and starts nothing.

    SIGINT, SIGTERM and SIGHUP stop the node cleanly (rclpy's own handlers are not installed:
    ``StopRequest`` notes the signal and the spin loop ends within 0.1 s). The node may define
    ``finished`` (property: stop spinning), ``exit_code`` and ``close(signum, detail)`` (called
    before destruction: after the end of the run, an error or a signal, whose number it gets,
    with ``detail`` saying if the parent process is gone).

    :returns: the process exit code (``iceskate_sim.exit_codes``): the node's ``exit_code``
        (0 without one); 2 if its arguments or parameters were refused, 1 if it could not start
        otherwise.
    """
    from rclpy.experimental import EventsExecutor
    argv = sys.argv[1:] if args is None else args[1:]
    own = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    if {'-h', '--help'} & set(own):
        print(usage(package, name, about, parameters))
        return 0
    node = None
    parent = os.getppid()
    with StopRequest() as stop:
        try:
            # every --params-file read as the scenes are (UTF-8, well-formed YAML): a bad one
            # is refused in one sentence naming it before rcl parses it
            given = sys.argv if args is None else args
            for option, value in zip(given, given[1:], strict=False):
                if option == '--params-file':
                    read_yaml(value, 'parameter file')
            loopback_dds(os.environ)
            init_ros(args)
            node = make()
            executor = EventsExecutor()
            executor.add_node(node)
            spin_until(executor, lambda: stop.requested or getattr(node, 'finished', False))
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except SimulationError as exc:  # ConfigError among them
            return error_exit(name, exc)
        except Exception as exc:  # a node that could not be made
            if node is None:
                return error_exit(name, exc, f'{type(exc).__name__}: {exc}')
            raise
        finally:
            if node is not None:
                close = getattr(node, 'close', None)
                if close is not None:
                    gone = os.getppid() != parent or not process_alive(parent)
                    close(stop.signum, f'its parent process {parent} ended' if gone else '')
                node.destroy_node()
            rclpy.try_shutdown()
        code = int(getattr(node, 'exit_code', 0) or 0)
    # The node is over: a stop signal now (e.g. a launcher's, while the interpreter ends) has
    # nothing left to stop and must not turn a clean end into a death by signal.
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    return code
