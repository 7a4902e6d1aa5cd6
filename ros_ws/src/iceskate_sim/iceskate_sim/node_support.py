"""What every iceskate node shares: QoS, parameter declaration and the Jazzy main() idiom.

* ``STATE_QOS``: reliable, keep-last 10, volatile (what the state and command topics are
  published with: every reader matches it);
  ``LOCKSTEP_READER_QOS``: best effort, keep-last 10, volatile (the lockstep's own readers);
  ``LATCHED_QOS``: transient-local depth 1 (robot_description).
* ``declare``: one parameter with a default and a ``ParameterDescriptor`` (description, range);
  a value out of range or of the wrong type raises ``ConfigError`` naming the parameter, and so
  does a parameter the node does not have (``check_unknown``: a typo in a params file);
  ``declare_all``: a table of them at once, then ``check_unknown``.
* ``run_node``: rclpy.init, construct, spin an ``EventsExecutor`` with a ``spin_once`` loop
  (its ``spin()`` busy-waits and ignores SIGTERM in rclpy 7.1), stop on SIGTERM/SIGINT
  (``ExternalShutdownException``), destroy and shut down; a ``ConfigError`` or
  ``SimulationError`` while starting exits 1 with one line naming the problem.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import sys
from types import SimpleNamespace
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from iceskate_sim.errors import SimulationError

STATE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: The lockstep's readers (the controllers' state, the simulator's commands): best effort, so
#: no acknowledgement goes back per message (a reliable writer serves a best-effort reader
#: without them); a message lost is recovered by the simulator's resend of an unanswered state.
LOCKSTEP_READER_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
                                 durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /clock: reliable writers match best-effort readers too (rclpy's TimeSource reads it so).
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class ConfigError(ValueError):
    """A node parameter (or the scene it names) is unusable; the message names it."""


def declare(node: Node, name: str, default: Any, description: str,
            low: float | None = None, high: float | None = None) -> Any:
    """Declare a parameter with a descriptor and return its value.

    :param low: inclusive lower bound of a float parameter (also gives the descriptor range).
    :param high: inclusive upper bound of a float parameter.
    :raises ConfigError: wrong type or out of range, naming the parameter.
    """
    descriptor = ParameterDescriptor(description=description)
    if low is not None or high is not None:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(low if low is not None else -sys.float_info.max),
            to_value=float(high if high is not None else sys.float_info.max), step=0.0)]
    try:
        value = node.declare_parameter(name, default, descriptor).value
    except ParameterException as exc:
        raise ConfigError(f'parameter {name!r}: {exc}') from None
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    return value


def declare_all(node: Node, table: Iterable[tuple[str, Any, str, tuple[float, float] | None]]
                ) -> SimpleNamespace:
    """Declare (name, default, description, float bounds or None) rows; refuse unknown ones.

    :returns: the values as attributes named like the parameters.
    """
    values = {name: declare(node, name, default, text, *(bounds or ()))
              for name, default, text, bounds in table}
    check_unknown(node)
    return SimpleNamespace(**values)


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


def run_node(make: Callable[..., Node], name: str, args: list[str] | None = None) -> int:
    """The Jazzy main(): init, make the node, spin until it is finished or stopped.

    The node may define ``finished`` (property: stop spinning) and ``exit_code`` and
    ``close()`` (called before destruction, also after SIGTERM).

    :returns: the process exit code.
    """
    from rclpy.experimental import EventsExecutor
    node = None
    try:
        rclpy.init(args=args)
        node = make()
        executor = EventsExecutor()
        executor.add_node(node)
        spin_until(executor, lambda: getattr(node, 'finished', False))
        return int(getattr(node, 'exit_code', 0))
    except (KeyboardInterrupt, ExternalShutdownException):
        return int(getattr(node, 'exit_code', 0) or 0)
    except (ConfigError, SimulationError) as exc:
        print(f'{name}: error: {exc}', file=sys.stderr)
        return 1
    except Exception as exc:  # e.g. rclpy.init refusing a malformed params file
        if node is None:
            print(f'{name}: error: {type(exc).__name__}: {exc}', file=sys.stderr)
            return 1
        raise
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()
