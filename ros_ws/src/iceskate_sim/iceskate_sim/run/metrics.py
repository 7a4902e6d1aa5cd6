"""The sampled trajectory of a run and the figures computed from it (``metrics.json``)."""

from __future__ import annotations

from collections.abc import Collection, Iterator, Mapping
import contextlib
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
#: The top-level entries of ``metrics.json`` (``compute_metrics``): from ``head_error_rms`` on
#: only for a run with samples, ``head_error_final_max`` only for a scene with pushes.
METRIC_NAMES = (
    'scene', 'sim_time_s', 'wall_time_s', 'real_time_factor', 'steps', 'end', 'fell', 'failure',
    'interrupted', 'transitions', 'max_constraint_residual', 'max_constraint_drift',
    'physics_steps', 'dynamics_evaluations', 'suppressed_cycles', 'resolved_cycles', 'sources',
    'rejected_commands', 'head_error_rms', 'forward_distance_m', 'head_error_final_max',
    'mode_time_fraction', 'zmp_outside_support_fraction', 'edge_mode_fraction',
    'support_positions_m', 'mode_sequence_per_step', 'arm_swing', 'arm_swing_steady',
    'yaw_range_rad')


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
        """Add a block of samples: ``columns`` holds every column but the efforts (t, q, v,
        qdd, mode, side, pivot, step_index, multipliers, support forces, cop_y, psi, psi_d,
        applied; first axis: sample), ``efforts`` each source's (n, 18) generalized forces (0
        where it did not act)."""
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


def _arm_swing(shoulders: np.ndarray, mask: np.ndarray) -> dict[str, Any] | None:
    """Peak-to-peak [rad] of the shoulders q11 and q14 (``shoulders``: their two rows), their
    mean (the arm swing of ``arm_swing_ratio``) and their correlation over the samples of
    ``mask`` (None for fewer than 3)."""
    samples = np.count_nonzero(mask)
    if samples <= 2:
        return None
    q11, q14 = shoulders[0, mask], shoulders[1, mask]
    corr = (float(np.corrcoef(q11, q14)[0, 1])
            if np.std(q11) > 0 and np.std(q14) > 0 else float('nan'))
    swing11, swing14 = np.ptp(q11), np.ptp(q14)
    return {'q11_peak_to_peak': float(swing11), 'q14_peak_to_peak': float(swing14),
            'mean_peak_to_peak': float((swing11 + swing14) / 2.0),
            'corr_q11_q14': corr, 'samples': int(samples)}


def arm_swing_ratio(with_yaw: Mapping[str, Any], without_yaw: Mapping[str, Any]
                    ) -> float | None:
    """The arm-swing ratio: the shoulders' mean peak-to-peak from the 4th step to the end
    (``arm_swing.mean_peak_to_peak``) of a run with the torso-yaw input tau8 over that of the
    same scene without it, from the two runs' metrics (None where either fell or has no such
    window, or the one without does not swing)."""
    swing, reference = with_yaw.get('arm_swing'), without_yaw.get('arm_swing')
    if (with_yaw.get('fell') or without_yaw.get('fell') or not swing or not reference
            or reference['mean_peak_to_peak'] <= 0.0):
        return None
    return swing['mean_peak_to_peak'] / reference['mean_peak_to_peak']


#: The trajectory's columns the metrics are computed from (the others are not joined for them).
METRIC_COLUMNS = frozenset({'t', 'psi', 'psi_d', 'mode', 'pivot', 'cop_y', 'q', 'step_index'})


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
    psi, psi_d = a['psi'], a['psi_d']
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
    cop = a['cop_y']
    y0 = a['q'][:, 0]
    outside = flat & ~((cop >= y0 + SOLE_HEEL_Y) & (cop <= y0 + SOLE_TOE_Y))
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
    shoulders = a['q'][:, [11, 14]].T.copy()  # q11 and q14, each contiguous
    metrics['arm_swing'] = _arm_swing(shoulders, late)
    # the second half (in time) of that window: the swing once the transients have decayed
    t_half = (t[late][0] + t[-1]) / 2.0 if np.any(late) else np.inf
    metrics['arm_swing_steady'] = _arm_swing(shoulders, late & (t >= t_half))
    metrics['yaw_range_rad'] = [float(a['q'][:, 8].min()), float(a['q'][:, 8].max())]
    return metrics
