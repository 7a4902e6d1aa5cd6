"""The sampled trajectory of a run and the figures computed from it (``metrics.json``)."""

from __future__ import annotations

from collections.abc import Collection, Iterator, Mapping, Sequence
import contextlib
from dataclasses import dataclass
import math
import os
import pathlib
import shutil
import tempfile
from typing import Any
import weakref
import zipfile

import numpy as np

from iceskate_sim.errors import RunInterrupted, SimulationError
from iceskate_sim.model.robot import SOLE_HEEL_Y, SOLE_TOE_Y

ARM_SWING_FROM_STEP = 3  # step_index >= 3: the paper's 4th step on, arm inputs removed
#: The right and left shoulder pitch, q11 and q14 (coordinate indices, docs/model.md Table 2):
#: the arms whose swing the metrics measure.
SHOULDERS = (11, 14)
RIGHT_SHOULDER, LEFT_SHOULDER = SHOULDERS
TORSO_YAW = 8  # q8, the torso yaw driven by the input tau8

#: What a fall does to a metric (``Metric.fall``).
FALL_RULES = {
    'kept': 'a run that fell has it, computed up to the fall',
    'none when fell': 'None when the run, or either run of a ratio, fell or failed',
}


@dataclass(frozen=True)
class Metric:
    """One figure of a run a user sees.

    :param name: as in ``metrics.json`` and the study table's columns, dotted inside a block
        (``arm_swing.corr_q11_q14``).
    :param unit: 'm', 's', 'rad', '-' (a count, a flag, a dimensionless figure), '×' (a ratio
        of like quantities), '' (text, a list or a block of several units).
    :param label: its meaning in a few words, for a plot (the unit apart: ``caption``).
    :param inputs: what it is computed from: trajectory columns (``q[11]``: one coordinate),
        the simulation's state (``sim.*``), or, for a ratio, the metrics of two runs.
    :param fall: what a fall does to it, a key of ``FALL_RULES``.
    :param by: the function, or the part of ``compute_metrics``, that computes it.
    :param ratio_of: a ratio: the metrics whose mean in one run it divides by their mean in the
        baseline run (``metric_ratio``); () for a metric of one run.
    """

    name: str
    unit: str
    label: str
    inputs: tuple[str, ...]
    fall: str = 'kept'
    by: str = 'compute_metrics'
    ratio_of: tuple[str, ...] = ()

    @property
    def caption(self) -> str:
        """The label with its unit, e.g. 'forward distance of the head [m]'."""
        return f'{self.label} [{self.unit}]' if self.unit else self.label


_HEAD = {'y': ('m', 'forward position'), 'z': ('m', 'height'), 'pitch': ('rad', 'pitch')}
_CORRELATION = ('corr(q11, q14): Pearson correlation of the shoulder angles over the window, '
                'raw (not detrended); -1: mirror images, the anti-phase swing of tau8')


def _swing_block(block: str, window: str, mask: str) -> tuple[Metric, ...]:
    """The entries of an arm-swing block (``_arm_swing`` over the samples of ``mask``)."""
    shoulders = tuple(f'q[{j}]' for j in SHOULDERS)
    return (
        Metric(block, '', f'arm swing, {window}', (*shoulders, 't', 'step_index'),
               by=f'_arm_swing over {mask}; None for fewer than 3 samples (fewer than 4 steps)'),
        Metric(f'{block}.q11_peak_to_peak', 'rad', f'q11 peak to peak, {window}',
               shoulders[:1], by='_arm_swing: np.ptp'),
        Metric(f'{block}.q14_peak_to_peak', 'rad', f'q14 peak to peak, {window}',
               shoulders[1:], by='_arm_swing: np.ptp'),
        Metric(f'{block}.mean_peak_to_peak', 'rad', f'mean q11, q14 peak to peak, {window}',
               shoulders, by='_arm_swing: the mean of the two peak-to-peak'),
        Metric(f'{block}.corr_q11_q14', '-', f'corr(q11, q14), {window}', shoulders,
               by=f'shoulder_correlation: {_CORRELATION}'),
        Metric(f'{block}.samples', '-', f'samples, {window}', ('step_index', 't'),
               by='_arm_swing'),
    )


def _head_block(block: str, what: str, by: str) -> tuple[Metric, ...]:
    """A block of the head's error (target minus pose) per coordinate."""
    return (Metric(block, '', what, ('psi', 'head_target'), by=by),
            *(Metric(f'{block}.{axis}', unit, f'{what}, {meaning}', ('psi', 'head_target'), by=by)
              for axis, (unit, meaning) in _HEAD.items()))


#: The registry: every figure of ``metrics.json`` (``compute_metrics``, in its order; blocks
#: followed by their entries) and the figures derived from two runs' metrics (``ratio_of``).
METRICS: dict[str, Metric] = {m.name: m for m in (
    Metric('scene', '', 'scene name', ('scene',)),
    Metric('sim_time_s', 's', 'simulated time', ('sim.time',)),
    Metric('wall_time_s', 's', "wall-clock time of the run's loop", ('wall time',)),
    Metric('real_time_factor', '×', 'simulated over wall-clock time',
           ('sim_time_s', 'wall_time_s')),
    Metric('steps', '-', 'support exchanges', ('sim.state.step_index',)),
    Metric('end', '', 'how the run ended', ('error', 'sim.ended'),
           by="compute_metrics: completed, fell, or the error's end"),
    Metric('fell', '-', 'fraction of runs that fell', ('end',),
           by="compute_metrics: end == 'fell'"),
    Metric('failure', '', 'why the run ended early (None: it completed)', ('error', 'sim.ended')),
    Metric('interrupted', '-', 'stopped by a signal', ('error',)),
    Metric('transitions', '-', 'mode transitions', ('sim.events',)),
    Metric('max_constraint_residual', '', 'largest constraint residual of the states',
           ('sim.stats',)),
    Metric('max_constraint_drift', '', 'largest constraint drift before a projection',
           ('sim.stats',)),
    Metric('physics_steps', '-', 'integrator steps', ('sim.stats',)),
    Metric('dynamics_evaluations', '-', 'dynamics evaluations', ('sim.stats',)),
    Metric('suppressed_cycles', '-', 'suppressed transition cycles', ('sim.stats',)),
    Metric('resolved_cycles', '-', 'resolved transition cycles', ('sim.stats',)),
    Metric('sources', '', 'input sources', ('tau_*',)),
    Metric('rejected_commands', '', 'commands the simulator node refused', ('LoopMonitor',)),
    *_head_block('head_error_rms', 'RMS head error', 'compute_metrics: _rms of psi_d - psi'),
    Metric('forward_distance_m', 'm', 'forward distance of the head', ('psi',)),
    *_head_block('head_error_final_max', 'largest head error in the last second after the '
                 'pushes', 'compute_metrics: max |psi_d - psi| (scenes with pushes only)'),
    Metric('mode_time_fraction', '-', 'share of the time in each gait mode', ('mode',)),
    Metric('zmp_outside_support_fraction', '-', 'share of flat-sole time with the ZMP off '
           'the sole', ('pivot', 'zmp_y', 'q[0]')),
    Metric('edge_mode_fraction', '-', 'share of the time on a sole edge', ('pivot',)),
    Metric('support_positions_m', 'm', 'support foot position at each step',
           ('q[0]', 'step_index')),
    Metric('mode_sequence_per_step', '', 'gait modes of each step', ('mode', 'step_index')),
    *_swing_block('arm_swing', 'from the 4th step', f'step_index >= {ARM_SWING_FROM_STEP}'),
    *_swing_block('arm_swing_steady', 'second half from the 4th step',
                  'the second half (in time) of that window'),
    Metric('yaw_range_rad', 'rad', 'torso yaw range', (f'q[{TORSO_YAW}]',)),
    Metric('arm_swing_ratio', '×', 'arm swing over the swing without yaw',
           ('arm_swing.mean_peak_to_peak', 'fell', 'failure'), fall='none when fell',
           by='arm_swing_ratio (metric_ratio): the run with tau8 over the same scene without',
           ratio_of=('arm_swing.mean_peak_to_peak',)),
)}
#: The top-level entries of ``metrics.json`` (``compute_metrics``): from ``head_error_rms`` on
#: only for a run with samples, ``head_error_final_max`` only for a scene with pushes.
METRIC_NAMES = tuple(name for name, m in METRICS.items() if '.' not in name and not m.ratio_of)


#: In-memory size [bytes] above which a Trajectory with a spill directory moves its samples
#: to files there (a long run's memory stays flat).
SPILL_BYTES = 64 * 2**20
_SPILL_CHUNK = 65536  # rows written at a time when a column is filled with zeros


class Trajectory:
    """Columns of per-control-instant samples, grown by blocks of samples (``extend``).

    :param spill: where to move the samples once more than ``spill_bytes`` are held: a
        private temporary directory made in this one on the first move, one raw file per
        column appended to (``arrays`` then maps them), removed with the Trajectory or at exit;
        None: all in memory.
    :param spill_bytes: see ``spill``.
    """

    def __init__(self, spill: pathlib.Path | None = None,
                 spill_bytes: int = SPILL_BYTES) -> None:
        self._blocks: dict[str, list[np.ndarray]] = {}  # arrays of whole blocks, in order
        self._count = 0
        self.sources: list[str] = []
        self._spill_parent = spill
        self._spill_dir: pathlib.Path | None = None  # made on the first move
        self._spill_bytes = spill_bytes
        self._held = 0  # bytes of the blocks in memory
        self._spilled = 0  # samples moved to the files
        self._layout: dict[str, tuple[np.dtype, tuple[int, ...]]] = {}  # of the spilled columns

    def extend(self, columns: dict[str, np.ndarray], efforts: dict[str, np.ndarray]) -> None:
        """Add a block of samples: ``columns`` holds every column but the efforts (the sample's
        saved columns, ``iceskate_native.sample.SAVED_COLUMNS``, and psi; first axis: sample),
        ``efforts`` each source's (n, 18) generalized forces (0 where it did not act)."""
        self._add_sources(efforts)
        n = len(columns['t'])
        for source in self.sources:
            columns = {**columns, f'tau_{source}': efforts.get(source, np.zeros((n, 18)))}
        for key, values in columns.items():
            self._blocks.setdefault(key, []).append(np.asarray(values))
            self._held += self._blocks[key][-1].nbytes
        self._count += n
        if self._spill_parent is not None and self._held > self._spill_bytes:
            self._spill()

    def _add_sources(self, efforts: dict[str, np.ndarray]) -> None:
        """New source columns, 0 for the samples before.

        :raises SimulationError: (``io_error``) when the zeros of the spilled samples cannot
            be written (the source is then not added).
        """
        for source in efforts:
            if source not in self.sources:
                key = f'tau_{source}'
                if self._spilled:  # the spilled samples' zeros go straight to its file
                    try:
                        self._write(key, np.zeros((self._spilled, 18)))
                    except OSError as exc:
                        self._file(key).unlink(missing_ok=True)
                        self._layout.pop(key, None)
                        raise self._spill_failed(exc) from None
                self.sources.append(source)
                self._blocks[key] = [np.zeros((self._count - self._spilled, 18))]

    def _spill(self) -> None:
        """Append every column's blocks to its file (all rows are in blocks), all or none.

        :raises SimulationError: (``io_error``) when a file cannot be written (a full disk):
            the files are then as before and the blocks kept.
        """
        if self._spill_dir is None:
            self._spill_parent.mkdir(parents=True, exist_ok=True)
            self._spill_dir = pathlib.Path(tempfile.mkdtemp(prefix='.trajectory-',
                                                            dir=self._spill_parent))
            weakref.finalize(self, shutil.rmtree, self._spill_dir, True)
        sizes = {key: self._file(key).stat().st_size if self._file(key).exists() else 0
                 for key in self._blocks}
        try:
            for key, blocks in self._blocks.items():
                for block in blocks:
                    self._write(key, block)
        except OSError as exc:
            for key, size in sizes.items():
                if self._file(key).exists():
                    os.truncate(self._file(key), size)
            raise self._spill_failed(exc) from None
        self._blocks = {key: [] for key in self._blocks}
        self._spilled = self._count
        self._held = 0

    def _spill_failed(self, exc: OSError) -> SimulationError:
        """The ``io_error`` of a spill file that could not be written."""
        return SimulationError(f"cannot write the trajectory's columns into "
                               f'{self._spill_parent}: {exc.strerror or exc}', end='io_error')

    def _file(self, key: str) -> pathlib.Path:
        """The spill file of column ``key``."""
        return self._spill_dir / f'{key}.bin'

    def _write(self, key: str, block: np.ndarray) -> None:
        """Append a block of column ``key`` to its spill file (zeros in chunks)."""
        block = np.asarray(block)
        layout = self._layout.setdefault(key, (block.dtype, block.shape[1:]))
        if (block.dtype, block.shape[1:]) != layout:
            block = block.astype(layout[0])
        with self._file(key).open('ab') as stream:
            for start in range(0, len(block), _SPILL_CHUNK):
                stream.write(np.ascontiguousarray(block[start:start + _SPILL_CHUNK]).tobytes())

    def __len__(self) -> int:
        """Number of samples."""
        return self._count

    def arrays(self, keys: Collection[str] | None = None) -> dict[str, np.ndarray]:
        """Every column (or those of ``keys``) as a numpy array (first axis: sample); read-only
        maps of the spill files once samples were spilled."""
        return dict(self.columns(keys))

    def columns(self, keys: Collection[str] | None = None
                ) -> Iterator[tuple[str, np.ndarray]]:
        """(name, array) of each column (or of those of ``keys``) in turn, as ``arrays`` gives
        them: a spilled column is mapped only while the caller holds it, so reading them one
        after the other keeps one column resident at a time (on a full disk, the rows not
        spilled are joined to it in memory)."""
        if not self._spilled:
            for key, blocks in self._blocks.items():
                if keys is None or key in keys:
                    yield key, np.concatenate(blocks)
            return
        with contextlib.suppress(SimulationError):  # a full disk: the rest stays in memory
            self._spill()
        for key, (dtype, shape) in self._layout.items():
            if keys is not None and key not in keys:
                continue
            spilled = np.memmap(self._file(key), dtype=dtype, mode='r',
                                shape=(self._spilled, *shape))
            yield key, (np.concatenate([spilled, *self._blocks[key]]) if self._blocks[key]
                        else spilled)

    def save(self, path: pathlib.Path) -> None:
        """Write the columns to an ``.npz`` file (what ``np.load`` reads), one after the other:
        integer columns and those at least three quarters zeros (the codes, the torques of
        sources that drive few joints) deflated at zlib level 1, the others stored as they are
        (zlib gains a tenth of dense floats for several times the time): 23.6 -> 14.6 MB for
        15 s of skate, for 0.03 s (12.1 MB for 0.08 s with the half-zero ones too)."""
        with zipfile.ZipFile(path, 'w', zipfile.ZIP_DEFLATED, allowZip64=True,
                             compresslevel=1) as archive:
            for key, column in self.columns():
                deflate = (column.dtype.kind in 'biu'
                           or np.count_nonzero(column) <= column.size // 4)
                member = f'{key}.npy' if deflate else zipfile.ZipInfo(f'{key}.npy')  # stored
                with archive.open(member, 'w', force_zip64=True) as stream:
                    np.lib.format.write_array(stream, column, allow_pickle=False)
                del column  # unmapped before the next one is read


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float('nan')


def _runs(values: np.ndarray) -> list[int]:
    """Collapse consecutive repeats: [1, 1, 2, 2, 10] -> [1, 2, 10]."""
    first = np.ones(values.shape, dtype=bool)  # where a run starts
    np.not_equal(values[1:], values[:-1], out=first[1:])
    return values[first].tolist()


def shoulder_correlation(q11: np.ndarray, q14: np.ndarray) -> float:
    """corr(q11, q14): the Pearson correlation of the shoulder angles [rad] of the same samples,
    raw (not detrended; -1: mirror images); nan for fewer than 3 samples or a still shoulder."""
    if q11.size < 3 or not (np.std(q11) > 0.0 and np.std(q14) > 0.0):
        return float('nan')
    return float(np.corrcoef(q11, q14)[0, 1])


def _arm_swing(shoulders: np.ndarray, mask: np.ndarray) -> dict[str, Any] | None:
    """An arm-swing block (``METRICS``): peak-to-peak [rad] of the shoulders q11 and q14
    (``shoulders``: their two rows), their mean (the arm swing of ``arm_swing_ratio``) and their
    correlation over the samples of ``mask`` (None for fewer than 3)."""
    samples = np.count_nonzero(mask)
    if samples <= 2:
        return None
    q11, q14 = shoulders[0, mask], shoulders[1, mask]
    swing11, swing14 = np.ptp(q11), np.ptp(q14)
    return {'q11_peak_to_peak': float(swing11), 'q14_peak_to_peak': float(swing14),
            'mean_peak_to_peak': float((swing11 + swing14) / 2.0),
            'corr_q11_q14': shoulder_correlation(q11, q14), 'samples': int(samples)}


def metric_value(metrics: Mapping[str, Any], name: str) -> Any:
    """Metric ``name`` (dotted, ``METRICS``) of a run: from its ``metrics.json`` (blocks nested)
    or its row of a study's table (dotted columns); None where it has none."""
    if name in metrics:
        return metrics[name]
    node: Any = metrics
    for part in name.split('.'):
        node = node.get(part) if isinstance(node, Mapping) else None
    return node


def completed(metrics: Mapping[str, Any]) -> bool:
    """Whether a run ran its whole duration: it did not fall (``fell``) and has no ``failure``
    (a fall, a failure, a signal); metrics without either count as completed."""
    return not metric_value(metrics, 'fell') and metric_value(metrics, 'failure') is None


def _mean(metrics: Mapping[str, Any], names: Sequence[str]) -> float | None:
    """The mean of the metrics ``names`` of a run (None if one is no number, or NaN)."""
    values = [metric_value(metrics, name) for name in names]
    if any(isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v)
           for v in values):
        return None
    return float(np.mean(values))


def metric_ratio(names: Sequence[str], run: Mapping[str, Any], baseline: Mapping[str, Any]
                 ) -> float | None:
    """A ratio of two runs (each its ``metrics.json`` or its row of a study's table): the mean
    of the metrics ``names`` of ``run`` over their mean in ``baseline``. None (``FALL_RULES``
    'none when fell') when either run fell or failed (``completed``), either has no value
    (``arm_swing`` of a run of fewer than 4 steps), or the baseline's mean is 0 (its arms did
    not swing)."""
    if not (completed(run) and completed(baseline)):
        return None
    top, bottom = _mean(run, names), _mean(baseline, names)
    if top is None or bottom is None or bottom == 0.0:
        return None
    return top / bottom


def arm_swing_ratio(with_yaw: Mapping[str, Any], without_yaw: Mapping[str, Any]
                    ) -> float | None:
    """``METRICS['arm_swing_ratio']``: the shoulders' mean peak-to-peak from the 4th step to the
    end (``arm_swing.mean_peak_to_peak``) of a run with the torso-yaw input tau8 over that of
    the same scene without it (``metric_ratio``: None when either fell or failed, has no such
    window, or the one without does not swing)."""
    return metric_ratio(METRICS['arm_swing_ratio'].ratio_of, with_yaw, without_yaw)


#: The trajectory's columns the metrics are computed from (the others are not joined for them).
METRIC_COLUMNS = frozenset({'t', 'psi', 'head_target', 'mode', 'pivot', 'zmp_y', 'q',
                            'step_index'})


def compute_metrics(scene: Any, sim: Any, trajectory: Trajectory, wall_time: float,
                    error: SimulationError | None) -> dict[str, Any]:
    """The figures of a run (see the README's metrics table)."""
    a = trajectory.arrays(METRIC_COLUMNS)
    sim_time = float(sim.time)
    failure = str(error) if error is not None else sim.ended
    interrupted = isinstance(error, RunInterrupted)  # stopped from outside: not a fall
    end = (error.end if error is not None
           else 'fell' if sim.ended is not None else 'completed')
    metrics: dict[str, Any] = {
        'scene': scene.name, 'sim_time_s': sim_time, 'wall_time_s': wall_time,
        'real_time_factor': sim_time / wall_time if wall_time > 0 else float('nan'),
        'steps': int(sim.state.step_index), 'end': end, 'fell': end == 'fell',
        'failure': failure, 'interrupted': interrupted, 'transitions': len(sim.events),
        'max_constraint_residual': float(sim.stats.max_constraint_residual),
        'max_constraint_drift': float(sim.stats.max_constraint_drift),
        'physics_steps': sim.stats.steps, 'dynamics_evaluations': sim.stats.evaluations,
        'suppressed_cycles': sim.stats.suppressed_cycles,
        'resolved_cycles': sim.stats.resolved_cycles,
        'sources': list(trajectory.sources),
        # commands the simulator node refused (its LoopMonitor fills it in; none headless)
        'rejected_commands': {'count': 0, 'by_reason': {}, 'first': []},
    }
    if not len(trajectory):
        return metrics
    psi, psi_d = a['psi'], a['head_target']
    err = psi_d - psi
    metrics['head_error_rms'] = {'y': _rms(err[:, 0]), 'z': _rms(err[:, 1]),
                                 'pitch': _rms(err[:, 2])}
    metrics['forward_distance_m'] = float(psi[-1, 0] - psi[0, 0])
    pushes = getattr(scene, 'pushes', ())
    t = a['t']
    push_end = max((p.start + p.duration for p in pushes), default=float('inf'))
    after = t >= max(push_end, t[-1] - 1.0)
    if pushes and np.any(after):  # recovery: worst head error in the last second, after pushes
        metrics['head_error_final_max'] = {
            'y': float(np.max(np.abs(err[after, 0]))), 'z': float(np.max(np.abs(err[after, 1]))),
            'pitch': float(np.max(np.abs(err[after, 2])))}
    modes = a['mode']
    entered, counts = np.unique(modes, return_counts=True)
    metrics['mode_time_fraction'] = {
        str(m): count / modes.size for m, count in zip(entered.tolist(), counts.tolist(),
                                                       strict=True)}
    flat = a['pivot'] == 0
    zmp_y = a['zmp_y']
    y0 = a['q'][:, 0]
    outside = flat & ~((zmp_y >= y0 + SOLE_HEEL_Y) & (zmp_y <= y0 + SOLE_TOE_Y))
    metrics['zmp_outside_support_fraction'] = float(np.mean(outside))
    metrics['edge_mode_fraction'] = float(np.mean(~flat))
    steps = np.asarray(a['step_index'])
    # each step's samples (step_index never decreases in a run): [start, end) per step
    bounds = np.searchsorted(steps, np.arange(int(steps.max()) + 2))
    metrics['support_positions_m'] = [float(y0[start] if end > start else y0[0])
                                      for start, end in zip(bounds[:-1], bounds[1:], strict=True)]
    metrics['mode_sequence_per_step'] = {str(k): _runs(modes[start:end]) for k, (start, end)
                                         in enumerate(zip(bounds[:-1], bounds[1:], strict=True))}
    late = steps >= ARM_SWING_FROM_STEP
    shoulders = a['q'][:, list(SHOULDERS)].T.copy()  # q11 and q14, each contiguous
    metrics['arm_swing'] = _arm_swing(shoulders, late)
    # the second half (in time) of that window: the swing once the transients have decayed
    t_half = (t[late][0] + t[-1]) / 2.0 if np.any(late) else np.inf
    metrics['arm_swing_steady'] = _arm_swing(shoulders, late & (t >= t_half))
    yaw = a['q'][:, TORSO_YAW]
    metrics['yaw_range_rad'] = [float(yaw.min()), float(yaw.max())]
    return metrics
