"""``ros2 run iceskate_analysis replay <bag> [--rate X | --fast]``: republish a recorded bag.

Every topic as recorded (raw CDR bytes, log-time pacing scaled by ``rate``, from ``RATES``),
``/clock`` synthesized when the bag has none; a bag never closed or cut is read as far as it
reached the disk (``bag_io.open_bag``), and the notes of the bag (rebuilt, gaps) go to stderr as
coupling_analysis gives them (docs/usage.md). Exit status (``iceskate_sim.exit_codes``) 0; 2
with one line for a bag or argument it refuses; 130, 143 or 129 with one line on SIGINT, SIGTERM
or SIGHUP, answered within ``WAIT_SLICE``; 1 for any other failure.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pathlib
import sys
import time
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock

from iceskate_analysis.bag_io import open_bag
from iceskate_sim.errors import InputRefused, RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.model.stamps import set_stamp
from iceskate_sim.ros.loopback import loopback_dds
from iceskate_sim.ros.node_support import CLOCK_QOS, LATCHED_QOS, init_ros
from iceskate_sim.shutdown import StopRequest, raise_if_stopped, say

#: The speed factors --rate takes (x recorded time); --fast plays without pacing.
RATES = (0.01, 100.0)
#: Longest wall time [s] a wait goes on without looking for a stop signal.
WAIT_SLICE = 0.05
#: Wall time [s] the subscribers of a topic get to acknowledge its last messages.
ACK_TIMEOUT = 2.0


def message_class(msgtype: str) -> type:
    """The rclpy message class of 'pkg/msg/Name'."""
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


class ReplayNode(Node):
    """Publishes the messages of one bag; every wait looks for a stop signal at least every
    ``WAIT_SLICE`` s.

    :ivar notes: what the reading of the bag found (rebuilt, gaps), as coupling_analysis says.
    :ivar count: messages published. :ivar reached: log time [ns] of the last (None: none).
    """

    def __init__(self, bag: pathlib.Path, stop: StopRequest, depth: int = 1000) -> None:
        super().__init__('replay')
        self.reader = open_bag(bag, stop)
        self.notes = [note for note in (self.reader.recovered, self.reader.gaps) if note]
        self.stop = stop
        self.publishers_by_topic: dict[str, Any] = {}
        for conn in self.reader.topics:
            if conn.topic in self.publishers_by_topic:
                continue
            qos = {'/clock': CLOCK_QOS, '/robot_description': LATCHED_QOS}.get(
                conn.topic, QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE))
            try:
                msg_class = message_class(conn.msgtype)
            except ImportError:  # e.g. /tf: no tf2_msgs Python package is installed here
                self.get_logger().warning(f'{conn.topic} ({conn.msgtype}) is not replayed: '
                                          'its message package is not installed')
                continue
            self.publishers_by_topic[conn.topic] = self.create_publisher(
                msg_class, conn.topic, qos)
        self._clock = None
        if '/clock' not in self.publishers_by_topic:
            self._clock = self.create_publisher(Clock, '/clock', CLOCK_QOS)
        self.connections = [c for c in self.reader.topics if c.topic in self.publishers_by_topic]
        self.count = 0
        self.reached: int | None = None

    def _check_stop(self) -> None:
        """:raises RunInterrupted: once a stop signal came."""
        if self.stop.requested:
            raise_if_stopped(self.stop, None if self.reached is None else self.reached * 1e-9,
                             f'{self.count} of {sum(c.count for c in self.connections)} '
                             'messages replayed')

    def _pause(self, seconds: float) -> None:
        """Wait ``seconds`` of wall time, in slices of ``WAIT_SLICE``.

        :raises RunInterrupted: on a stop signal.
        """
        end = time.monotonic() + seconds
        self._check_stop()
        while (left := end - time.monotonic()) > 0:
            time.sleep(min(left, WAIT_SLICE))
            self._check_stop()

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait until every topic has a subscriber (or ``timeout`` s); True if they all do.

        :raises RunInterrupted: on a stop signal.
        """
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in self.publishers_by_topic.values()):
                return True
            self._pause(0.01)
        return False

    def play(self, rate: float | None) -> int:
        """Publish every message; pace to ``rate`` x recorded time (None: no pacing); then give
        each topic's subscribers up to ``ACK_TIMEOUT`` s to acknowledge them.

        :raises RunInterrupted: on a stop signal.
        """
        start_wall, first, last_clock = time.monotonic(), None, None
        for conn, timestamp, raw in self.reader.messages(self.connections):
            first = timestamp if first is None else first
            self._pause(0.0 if rate is None else
                        start_wall + (timestamp - first) / 1e9 / rate - time.monotonic())
            if self._clock is not None and timestamp != last_clock:
                clock = Clock()
                set_stamp(clock.clock, timestamp)
                self._clock.publish(clock)
                last_clock = timestamp
            self.publishers_by_topic[conn.topic].publish(bytes(raw))
            self.count += 1
            self.reached = timestamp
        for publisher in self.publishers_by_topic.values():
            deadline = time.monotonic() + ACK_TIMEOUT
            while not publisher.wait_for_all_acked(Duration(seconds=WAIT_SLICE)) and \
                    time.monotonic() < deadline:
                self._check_stop()
        return self.count


def main(argv: list[str] | None = None) -> int:
    """Console entry point."""
    argv = sys.argv if argv is None else argv
    parser = argparse.ArgumentParser(prog='replay', description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=pathlib.Path, help='rosbag2 directory (MCAP)')
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument('--rate', type=float, default=1.0,
                      help=f'speed factor, {RATES[0]:g} to {RATES[1]:g} (default 1)')
    pace.add_argument('--fast', action='store_true', help='as fast as possible')
    parser.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='S',
                        help='first wait up to S s for a subscriber on every topic')
    args = parser.parse_args(remove_ros_args(argv)[1:])
    node = None
    with StopRequest() as stop:  # rclpy's own handlers are not installed (as ``run_node``)
        try:
            if not args.fast and not RATES[0] <= args.rate <= RATES[1]:
                raise InputRefused(f'--rate {args.rate:g} is outside {RATES[0]:g} to '
                                   f'{RATES[1]:g} (--fast plays without pacing)')
            loopback_dds(os.environ)
            init_ros(argv)
            node = ReplayNode(args.bag, stop)
            for note in node.notes:  # e.g. a bag rebuilt after a killed run
                say(f'replay: note: {note}')
            if args.wait_for_subscribers > 0 and not node.wait_for_subscribers(
                    args.wait_for_subscribers):
                node.get_logger().warning('not every topic has a subscriber; playing anyway')
            count = node.play(None if args.fast else args.rate)
            node.get_logger().info(f'replayed {count} messages from {args.bag}')
            return DONE
        except RunInterrupted as exc:
            say(f'replay: {exc}')
            return exc.exit_code
        except SimulationError as exc:  # e.g. a bag missing or unreadable, naming the file
            return error_exit('replay', exc)
        except Exception as exc:  # e.g. an unknown message type
            return error_exit('replay', exc, f'{args.bag}: {type(exc).__name__}: {exc}')
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()


if __name__ == '__main__':
    raise SystemExit(main())
