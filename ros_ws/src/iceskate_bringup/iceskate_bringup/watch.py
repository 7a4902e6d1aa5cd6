"""A run watched live (``run_scene SCENE --view``, headless or ``--ros``): the ``Watch`` the
options ask for and the page that shows it (docs/usage.md, "Watch the robot")."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

from iceskate_sim.shutdown import say

if TYPE_CHECKING:
    from iceskate_sim.model.robot import Robot
    from iceskate_viewer.live import LiveView


@dataclass(frozen=True)
class Watch:
    """A run watched live: its page on ``host``:``port``, at ``pace`` simulated seconds per
    wall second (0: as fast as it runs)."""

    pace: float = 1.0
    host: str = '127.0.0.1'
    port: int = 8080


def live_view(watch: Watch | None, robot: Robot, name: str,
              closing: contextlib.ExitStack) -> LiveView | None:
    """The live page of ``watch`` showing run ``name`` (None: not watched), closed with
    ``closing``; its address is printed."""
    if watch is None:
        return None
    from iceskate_viewer.live import LiveView
    from iceskate_viewer.pose import BodyPose
    live = LiveView(BodyPose(robot), name, watch.host, watch.port, watch.pace)
    closing.callback(live.close)
    say(f'run_scene: the live view is at {live.url} (pause and pace on the page)')
    return live
