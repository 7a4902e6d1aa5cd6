"""``ros2 run iceskate_analysis replay <bag> [--rate X | --fast]``: republish a recorded bag.

Every topic as recorded (raw CDR bytes, log-time pacing scaled by ``rate``), ``/clock``
synthesized when the bag has none; a bag never closed or cut is read as far as it reached the
disk (``bag_io.open_bag``), with a warning saying how much (docs/usage.md).
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
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock

from iceskate_analysis.bag_io import open_bag
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.stamps import set_stamp
from iceskate_sim.ros.loopback import loopback_dds
from iceskate_sim.ros.node_support import CLOCK_QOS, LATCHED_QOS


def message_class(msgtype: str) -> type:
    """The rclpy message class of 'pkg/msg/Name'."""
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


class ReplayNode(Node):
    """Publishes the messages of one bag."""

    def __init__(self, bag: pathlib.Path, depth: int = 1000) -> None:
        super().__init__('replay')
        self.reader = open_bag(bag)
        if self.reader.recovered:
            self.get_logger().warning(self.reader.recovered)
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
        self.count = 0

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait until every topic has a subscriber (or ``timeout`` s); True if they all do."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in self.publishers_by_topic.values()):
                return True
            time.sleep(0.01)
        return False

    def play(self, rate: float | None) -> int:
        """Publish every message; pace to ``rate`` x recorded time (None: no pacing)."""
        start_wall, first, last_clock = time.monotonic(), None, None
        connections = [c for c in self.reader.topics if c.topic in self.publishers_by_topic]
        for conn, timestamp, raw in self.reader.messages(connections):
            first = timestamp if first is None else first
            if rate is not None:
                delay = start_wall + (timestamp - first) / 1e9 / rate - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            if self._clock is not None and timestamp != last_clock:
                clock = Clock()
                set_stamp(clock.clock, timestamp)
                self._clock.publish(clock)
                last_clock = timestamp
            self.publishers_by_topic[conn.topic].publish(bytes(raw))
            self.count += 1
        for publisher in self.publishers_by_topic.values():
            publisher.wait_for_all_acked(Duration(seconds=2.0))
        return self.count


def main(argv: list[str] | None = None) -> int:
    """Console entry point."""
    argv = sys.argv if argv is None else argv
    parser = argparse.ArgumentParser(prog='replay', description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=pathlib.Path, help='rosbag2 directory (MCAP)')
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument('--rate', type=float, default=1.0, help='speed factor (default 1)')
    pace.add_argument('--fast', action='store_true', help='as fast as possible')
    parser.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='S',
                        help='first wait up to S s for a subscriber on every topic')
    args = parser.parse_args(remove_ros_args(argv)[1:])
    if not args.fast and not args.rate > 0:
        parser.error('--rate must be > 0')
    loopback_dds(os.environ)
    rclpy.init(args=argv)
    node = None
    try:
        node = ReplayNode(args.bag)
        if args.wait_for_subscribers > 0 and not node.wait_for_subscribers(
                args.wait_for_subscribers):
            node.get_logger().warning('not every topic has a subscriber; playing anyway')
        count = node.play(None if args.fast else args.rate)
        node.get_logger().info(f'replayed {count} messages from {args.bag}')
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    except SimulationError as exc:  # bag missing or unreadable (its message names the file)
        print(f'replay: error: {exc}', file=sys.stderr)
        return 1
    except Exception as exc:  # e.g. an unknown message type
        print(f'replay: error: {args.bag}: {type(exc).__name__}: {exc}', file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    raise SystemExit(main())
