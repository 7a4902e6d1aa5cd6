"""The live view of a running simulation (``run_scene SCENE --view``, headless or ``--ros``).

The loop ``offer``s frames and never waits for the page: a frame goes into a queue of one,
replacing one not yet drawn, and a display thread draws the newest at ``DISPLAY_HZ`` of wall
time at the most. The page's pause and pace hold a headless loop in ``keep_pace`` (its only
wait: ``pace`` times real time, 0: as fast as it runs); a ROS run's simulator keeps them itself,
told by ``on_control``.
"""

from __future__ import annotations

from collections.abc import Callable
import queue
import sys
import threading
import time

from iceskate_sim.run.pace import MAX_PACE, PaceClock
from iceskate_sim.shutdown import StopRequest, say
from iceskate_viewer.page import RunPage, serve, stop_server, url_of
from iceskate_viewer.pose import BodyPose, ViewFrame

#: Frames drawn per second of wall time at the most.
DISPLAY_HZ = 30.0
#: Longest single wait [s] of ``keep_pace`` between two looks at a stop request.
WAIT_SLICE = 0.05
#: Frames in a row the page may fail to draw before the view stops drawing (one failed
#: frame is a race inside the web server's threads, and the next one is drawn).
FAILED_FRAMES = 30


class LiveView:
    """A page on ``host``:``port`` showing the run ``name`` as it goes.

    :param pace: simulated seconds per wall second (0: no pacing); also a control on the page.

    ``on_control(paused, pace)``, when set, is told every change of the page's controls.
    """

    def __init__(self, body: BodyPose, name: str, host: str, port: int, pace: float) -> None:
        self.server = serve(host, port)
        self.page = RunPage(self.server, body, [name])
        gui = self.server.gui
        self._pause = gui.add_checkbox('Pause', False)
        self._pace = gui.add_number('Pace (x real time, 0: fastest)', float(pace), min=0.0,
                                    max=MAX_PACE, step=0.1)
        self._pause.on_update(lambda _: self._controls_changed())
        self._pace.on_update(lambda _: self._controls_changed())
        self.on_control: Callable[[bool, float], None] | None = None
        self._frames: queue.Queue[ViewFrame] = queue.Queue(maxsize=1)
        self.dropped = 0  # frames replaced before they were drawn
        self._clock = PaceClock(pace)
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._display, name='live-view', daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """The page's address."""
        return url_of(self.server)

    @property
    def pace(self) -> float:
        """Simulated seconds per wall second the run keeps to (0: none)."""
        return self._clock.pace

    @property
    def paused(self) -> bool:
        """The page's pause is on."""
        return bool(self._pause.value)

    def offer(self, frame: ViewFrame) -> None:
        """Hand ``frame`` to the page without waiting (an undrawn older frame is dropped)."""
        while True:
            try:
                self._frames.put_nowait(frame)
                return
            except queue.Full:
                try:
                    self._frames.get_nowait()
                    self.dropped += 1
                except queue.Empty:
                    pass

    def offer_last(self, columns: dict) -> None:
        """``offer`` the last sample of a block of trajectory columns."""
        self.offer(ViewFrame.of_columns(columns, -1))

    def periods_per_frame(self, control_period: float) -> int:
        """Control periods of one drawn frame at the pace (a block of the paced loop, so that
        the robot moves smoothly); unpaced: no limit."""
        pace = self.pace
        if pace <= 0.0:
            return sys.maxsize
        return max(1, int(pace / DISPLAY_HZ / control_period))

    def keep_pace(self, t: float, stop: StopRequest) -> None:
        """Wait while the page is paused, then until simulated time ``t`` [s] is due at the
        pace; returns at once on a stop request."""
        while self.paused and not stop.requested and self._thread.is_alive():
            time.sleep(WAIT_SLICE)  # (a page that stopped drawing holds nothing)
        while not stop.requested and not self.paused:
            wait = self._clock.wait(t)  # (a new pace counts from its next look)
            if wait <= 0.0:
                return
            time.sleep(min(wait, WAIT_SLICE))

    def close(self) -> None:
        """Stop the display thread and the server."""
        self._closed.set()
        self._thread.join(timeout=5.0)
        stop_server(self.server)

    def _controls_changed(self) -> None:
        """The page's pause or pace changed: the pace counts anew (no catching up)."""
        self._clock.pace = max(0.0, float(self._pace.value))
        if self.on_control is not None:
            self.on_control(self.paused, self.pace)

    def _display(self) -> None:
        """Draw the newest frame at ``DISPLAY_HZ`` at the most; a frame the page fails to draw
        is said once, and after ``FAILED_FRAMES`` in a row the view stops (the run goes on)."""
        period, failed = 1.0 / DISPLAY_HZ, 0
        while not self._closed.is_set():
            try:
                frame = self._frames.get(timeout=0.1)
            except queue.Empty:
                continue
            started = time.perf_counter()
            try:
                self.page.show(0, frame)
                failed = 0
            except Exception as error:  # the page fails, the run goes on and finishes
                failed += 1
                if failed == 1 or failed == FAILED_FRAMES:
                    say(f'run_scene: the live view '
                        f'{"stopped drawing" if failed == FAILED_FRAMES else "missed a frame"} '
                        f'at t={frame.t:.3f} s: {type(error).__name__}: {error}')
                if failed == FAILED_FRAMES:
                    return
            self._closed.wait(max(0.0, period - (time.perf_counter() - started)))
