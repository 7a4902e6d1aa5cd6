"""One run of a sweep in a worker process (a local pool's or a Ray task's): its table row. The
process keeps the modules and the robot model loaded between runs; a signal during a run ends
it cleanly, without a row (the run is done again when the sweep resumes).
"""

from __future__ import annotations

from dataclasses import dataclass
import os
import pathlib
import shutil
import signal
import time
from typing import Any

from iceskate_sim.errors import RunInterrupted, SimulationError
from iceskate_sim.run.metrics import metric_value
from iceskate_sim.shutdown import STOP_SIGNALS, die_with_parent


@dataclass(frozen=True)
class Task:
    """What a worker needs for one run.

    :param key: the run's key (``iceskate_study.spec.run_key``).
    :param raw: the whole scene mapping (validated by the sweep).
    :param metrics: the metrics to keep (dotted names into ``metrics.json``).
    :param run_dir: folder for the run's files and bag (absolute), None: no files.
    """

    key: str
    raw: dict[str, Any]
    metrics: tuple[str, ...]
    run_dir: str | None = None


def warm_up() -> None:
    """Prepare a local pool's worker process: signals ignored between runs, SIGKILL on the
    sweep's death (its rows are lost anyway), modules and robot loaded."""
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    die_with_parent(signal.SIGKILL)
    import iceskate_bringup.composition  # noqa: F401  (the control laws)
    from iceskate_sim.model.robot import load_robot
    load_robot()


def select_metrics(metrics: dict[str, Any], names: tuple[str, ...]) -> dict[str, Any]:
    """The columns of ``names`` in ``metrics``: a dotted name's value (``metric_value``), a
    block's entries as ``block.entry`` (nested blocks flattened too); absent values are left
    out."""
    out: dict[str, Any] = {}

    def put(name: str, value: Any) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                put(f'{name}.{k}', v)
        elif value is not None:
            out[name] = value

    for name in names:
        put(name, metric_value(metrics, name))
    return out


def run_marked(task: Task, folder: str) -> dict[str, Any] | None:
    """``run_task``, with the run's key in ``folder/<pid>`` while it runs (so the sweep knows
    which run was in a worker process that died)."""
    mark = pathlib.Path(folder) / str(os.getpid())
    mark.write_text(task.key, encoding='ascii')
    try:
        return run_task(task)
    finally:
        mark.unlink(missing_ok=True)


def run_task(task: Task) -> dict[str, Any] | None:
    """Run ``task``; its row (status, failure, run folder, the worker's time [s] and the kept
    metrics), or None when a signal ended it (it has no row then)."""
    from iceskate_bringup.runner import simulate
    from iceskate_bringup.scene import parse_scene
    start = time.perf_counter()
    row: dict[str, Any] = {'key': task.key, 'status': 'failed', 'failure': None,
                           'run_dir': None}
    try:
        scene = parse_scene(task.raw)
        out = pathlib.Path(task.run_dir) if task.run_dir is not None else None
        if out is not None:
            shutil.rmtree(out, ignore_errors=True)  # an earlier, interrupted attempt
            row['run_dir'] = str(out)
        outcome = simulate(scene, out, progress=False)
        metrics, error = outcome.metrics, outcome.error
    except RunInterrupted:
        return None
    except SimulationError as exc:  # it could not start (e.g. its initial state)
        row['failure'] = str(exc)
    except Exception as exc:  # a bug in one run is that run's row, never the sweep's end
        row['failure'] = f'{type(exc).__name__}: {exc}'
    else:
        row['status'] = 'failed' if error is not None else 'fell' if metrics['fell'] else 'ok'
        row['failure'] = metrics['failure']
        row |= select_metrics(metrics, task.metrics)
    row['worker_time_s'] = time.perf_counter() - start
    return row
