"""Runs from Python, for notebooks and scripts (docs/usage.md, "From Python")::

    from iceskate_bringup.api import load_scene, run, with_overrides
    skate = run('skate', {'floor.mu': 0.01, 'duration': 5.0})
    skate.metrics['steps'], skate.columns['q'][:, 11], skate.events[0]['cause']

A scene is a shipped scene's name, a YAML path or a loaded ``Scene``; overrides are dotted scene
keys, checked as in a scene file (one-sentence ``SimulationError``). ``run`` is ``run_scene``'s
headless run (the same loop, at the same speed), its outputs written only when ``out`` is given.
"""

from __future__ import annotations

from collections.abc import Mapping
import copy
from dataclasses import asdict, dataclass
import pathlib
from typing import Any

import numpy as np

from iceskate_bringup.runner import simulate
from iceskate_bringup.scene import load_scene, parse_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.run.scene import Scene, set_keys

__all__ = ['Run', 'load_scene', 'run', 'with_overrides']


@dataclass(frozen=True)
class Run:
    """A finished run, in memory.

    :param scene: what ran.
    :param metrics: what ``metrics.json`` holds (``end``, ``steps``, ``arm_swing``, ...).
    :param columns: the samples, as in ``trajectory.npz`` (``t`` [s], ``q``, ``v``, ``qdd``
        (n, 18), ``mode``, ``psi``, ``tau_<source>``, ...; first axis: sample).
    :param events: every mode transition, as in ``events.json``.
    :param error: the failure of the physics or of a controller that ended the run (None: it
        completed or fell; ``metrics['end']`` says which).
    """

    scene: Scene
    metrics: dict[str, Any]
    columns: dict[str, np.ndarray]
    events: list[dict[str, Any]]
    error: SimulationError | None


def with_overrides(scene: Scene, overrides: Mapping[str, Any]) -> Scene:
    """``scene`` with the dotted keys of ``overrides`` set (e.g. ``{'floor.mu': 0.01,
    'inputs.gait_manager.yaw.amplitude': 20.0}``), validated whole.

    :raises SimulationError: for a bad key or value, naming it.
    """
    raw = copy.deepcopy(scene.raw)
    set_keys(raw, overrides)
    return parse_scene(raw)


def run(scene: Scene | str | pathlib.Path, overrides: Mapping[str, Any] | None = None,
        out: str | pathlib.Path | None = None, progress: bool = False) -> Run:
    """Run ``scene`` (with ``overrides``) headless; write its outputs into ``out`` if given.

    :raises SimulationError: for a bad scene or override, or an output folder refused.
    :raises RunInterrupted: after Ctrl-C (the outputs written).
    """
    scene = (load_scene(scene, overrides) if not isinstance(scene, Scene)
             else with_overrides(scene, overrides) if overrides else scene)
    outcome = simulate(scene, pathlib.Path(out) if out is not None else None, progress)
    session = outcome.session
    return Run(scene, outcome.metrics, session.trajectory.arrays(),
               [asdict(event) for event in session.sim.events], outcome.error)
