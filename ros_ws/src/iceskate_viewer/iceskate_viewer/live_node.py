"""The live view of a run through the ROS graph (``run_scene SCENE --ros --view``).

``LiveViewNode`` reads the simulator's ``gait_state`` (and visual lifting's head target from
``effort_commands``) best effort, so it never holds the lockstep back, and offers a frame to the
``LiveView`` at its display rate; the page's pause and pace go to the simulator (``~/pause``,
``~/resume``, its ``pace`` parameter), which keeps them. The simulator starts paused; the
node resumes it once the simulator's state publisher and every controller's command publisher
are matched and its services are up, so that a short run is seen from its start, head target
included.
``watching`` runs the node on its own context and executor thread for as long as the run goes.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
import contextlib
import threading
import time
from typing import Any

import numpy as np
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from std_srvs.srv import Trigger

from iceskate_interfaces.msg import EffortCommand, GaitState
from iceskate_sim.model.robot import SIDES
from iceskate_sim.ros.conversions import PIVOT_OF_CODE
from iceskate_sim.ros.node_support import LOCKSTEP_READER_QOS, spin_until
from iceskate_sim.shutdown import say
from iceskate_viewer.live import DISPLAY_HZ, LiveView
from iceskate_viewer.pose import ViewFrame

#: Latest commands kept (raw) to find the head target among: one per controller and period.
RECENT_COMMANDS = 4
#: Longest wait [s] for the simulator's state (and the controllers' commands) before the run is
#: let go unseen.
CONNECT_TIMEOUT = 60.0


def frame_of_gait_state(state: Any, head_target: np.ndarray) -> ViewFrame:
    """The ``ViewFrame`` of a ``GaitState`` message, with the head target (y, z) [m]."""
    stamp = state.header.stamp
    return ViewFrame(stamp.sec + stamp.nanosec * 1e-9, np.asarray(state.position, dtype=float),
                     int(state.mode), SIDES[state.support_side], PIVOT_OF_CODE[state.pivot],
                     int(state.step_index), head_target)


class LiveViewNode(Node):
    """Shows the run of the node ``simulator`` (with ``controllers`` command publishers) on
    ``live``, and drives its pause and pace."""

    def __init__(self, live: LiveView, controllers: int, simulator: str = 'simulator',
                 **kwargs: Any) -> None:
        super().__init__('live_view', **kwargs)
        self.live = live
        self._controllers = controllers
        self._commands: deque[bytes] = deque(maxlen=RECENT_COMMANDS)
        self._offered_at = -np.inf  # wall time [s] of the last frame offered
        self._lock = threading.Lock()  # the page's controls come from its worker threads
        self._connected = False  # the simulator has been told the page's controls
        self._told: tuple[bool, float] | None = None  # (paused, pace) it was told last
        self._states = self.create_subscription(GaitState, 'gait_state', self._on_state,
                                                LOCKSTEP_READER_QOS, raw=True)
        self._commands_in = self.create_subscription(
            EffortCommand, 'effort_commands', self._on_command, LOCKSTEP_READER_QOS, raw=True)
        self._pause = self.create_client(Trigger, f'/{simulator}/pause')
        self._resume = self.create_client(Trigger, f'/{simulator}/resume')
        self._parameters = AsyncParameterClient(self, simulator)
        live.on_control = self._control
        self._connect_by = time.monotonic() + CONNECT_TIMEOUT
        self._connecting = self.create_timer(0.05, self._connect)

    def _connect(self) -> None:
        """Tell the simulator (started paused) the page's controls, which resumes it unless the
        page is paused, once its state publisher and the controllers' command publishers are
        matched and its services are up; after ``CONNECT_TIMEOUT`` s without them anyway,
        saying so."""
        if not (self._resume.service_is_ready() and self._pause.service_is_ready()):
            return
        seen = (self._states.get_publisher_count() > 0
                and self._commands_in.get_publisher_count() >= self._controllers)
        if not seen and time.monotonic() < self._connect_by:
            return
        if not seen:
            self.get_logger().warning(f"the simulator's state or the controllers' commands did "
                                      f'not reach the live view within {CONNECT_TIMEOUT:g} s: '
                                      'the run goes on, maybe unseen')
        self._connecting.cancel()
        with self._lock:
            self._connected = True
        self._control()

    def let_go(self) -> None:
        """Resume the simulator if it was never told (this node stops before it connected)."""
        with self._lock:
            if not self._connected and self._resume.service_is_ready():
                self._resume.call_async(Trigger.Request())
            self._connected = True

    def _on_state(self, data: bytes) -> None:
        """A state: offered to the page when a frame is due (at ``DISPLAY_HZ`` at the most)."""
        now = time.monotonic()
        if now - self._offered_at < 1.0 / DISPLAY_HZ:
            return
        self._offered_at = now
        self.live.offer(frame_of_gait_state(deserialize_message(data, GaitState),
                                            self._head_target()))

    def _on_command(self, data: bytes) -> None:
        """A command (raw): kept among the latest ``RECENT_COMMANDS``."""
        self._commands.append(data)

    def _head_target(self) -> np.ndarray:
        """(y, z) [m] of the latest command that carries a head target (NaN: none)."""
        for data in reversed(list(self._commands)):
            target = deserialize_message(data, EffortCommand).head_target
            if len(target) >= 2:
                return np.asarray(target[:2], dtype=float)
        return np.full(2, np.nan)

    def _control(self, *_: object) -> None:
        """Tell the simulator the page's pause and pace where they differ from what it was
        told (nothing before ``_connect``, which tells it all); called by the page's threads."""
        with self._lock:
            if not self._connected:
                return
            paused, pace = self.live.paused, self.live.pace
            if self._told is None or paused != self._told[0]:
                call = (self._pause if paused else self._resume).call_async(Trigger.Request())
                call.add_done_callback(self._answered)
            if self._told is None or pace != self._told[1]:
                call = self._parameters.set_parameters([Parameter('pace', value=float(pace))])
                call.add_done_callback(self._answered)
            self._told = (paused, pace)

    def _answered(self, call: Any) -> None:
        """A call to the simulator came back: one line if it was refused."""
        answer = call.result()
        if answer is None:  # cancelled: the run is over
            return
        refused = (not answer.success if hasattr(answer, 'success')
                   else not all(r.successful for r in answer.results))
        if refused:
            self.get_logger().warning(f"the simulator refused the page's control: {answer}")


@contextlib.contextmanager
def watching(live: LiveView, domain_id: int, controllers: int) -> Iterator[LiveViewNode]:
    """A ``LiveViewNode`` on ``live`` in ROS domain ``domain_id`` (a graph of ``controllers``
    controller nodes), spun by its own thread until the block ends (the environment's DDS
    settings apply: set them first)."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)  # the run has its own
    node = executor = thread = None
    done = threading.Event()
    try:
        node = LiveViewNode(live, controllers, context=context)
        executor = EventsExecutor(context=context)
        executor.add_node(node)

        def spin() -> None:
            try:
                spin_until(executor, done.is_set, context)
            except Exception as error:  # the page stops following; the run goes on
                say(f'run_scene: the live view stopped: {type(error).__name__}: {error}')
                node.let_go()
        thread = threading.Thread(target=spin, name='live-view-node', daemon=True)
        thread.start()
        yield node
    finally:
        live.on_control = None
        done.set()
        if thread is not None:
            thread.join(timeout=5.0)
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        context.try_shutdown()
