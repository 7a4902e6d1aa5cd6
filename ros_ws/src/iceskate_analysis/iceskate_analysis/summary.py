"""The picture of a run, ``summary.png``, from its trajectory and metrics (no bag, no ROS): head
forward position, height and pitch against their targets, gait mode, shoulder angles and
forward speed over time, the support exchanges marked. Long series are decimated (min/max per
bucket) for drawing. ``summary DIR`` draws it for a run that has none (the nodes run by hand
write none); SIGINT, SIGTERM or SIGHUP end it with 128 + the signal's number and one line, the
picture not written.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Mapping
import json
import pathlib
import signal
import sys
import textwrap
from typing import TYPE_CHECKING, Any
import zipfile
import zlib

import numpy as np

from iceskate_analysis.outputs import StagedFiles
from iceskate_sim.errors import InputRefused, RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.shutdown import StopRequest, raise_if_stopped, say

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ['DRAWN_COLUMNS', 'SUMMARY_NAME', 'draw_picked', 'draw_summary', 'picked_columns',
           'write_summary']

SUMMARY_NAME = 'summary.png'
MAX_POINTS = 3000  # per drawn series (decimated above)
_DPI = 100
_SWING_GROUPS = ((1, 'A'), (5, 'Hs'), (9, 'Hp'), (13, 'Fs'), (17, 'Fp'))  # first mode: swing
#: The swing foot's states of docs/model.md §3.2, in words (the mode panel's key).
_SWING_KEY = ('swing foot (right): A air · Hs/Hp heel sliding/pinned · '
              'Fs/Fp sole flat sliding/stuck')
#: The trajectory's columns the picture is drawn from (q: its shoulders q11 and q14).
DRAWN_COLUMNS = ('t', 'psi', 'head_target', 'mode', 'side', 'step_index', 'q')
#: Clip a panel only for a blow-up: samples reaching ~50 times the bulk's span.
_DIVERGENCE = {'percentile': 1.0, 'margin': 1.0, 'reach': 24.5}


def draw_summary(columns: Iterable[tuple[str, np.ndarray]], metrics: Mapping[str, Any],
                 path: pathlib.Path) -> pathlib.Path:
    """Draw ``path`` (a PNG) from a run's trajectory columns, (name, array) pairs as
    ``Trajectory.columns`` gives them (t, psi, psi_d, mode, side, step_index and q are drawn),
    and its metrics.

    :return: ``path``.
    :raises InputRefused: when a column is missing or holds no sample.
    """
    return draw_picked(picked_columns(columns), metrics, path)


def picked_columns(columns: Iterable[tuple[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """What the picture is drawn from, copied out of (name, array) pairs as
    ``Trajectory.columns`` gives them: t, psi, psi_d, mode, side, step_index, and q's
    shoulders as ``shoulders`` (n, 2)."""
    from iceskate_sim.run.metrics import SHOULDERS
    a: dict[str, np.ndarray] = {}
    for key, column in columns:  # one spilled column mapped at a time
        if key == 'q':
            a['shoulders'] = np.array(column[:, list(SHOULDERS)])
        elif key in DRAWN_COLUMNS:
            a[key] = np.array(column)
    return a


def draw_picked(a: dict[str, np.ndarray], metrics: Mapping[str, Any], path: pathlib.Path
                ) -> pathlib.Path:
    """``draw_summary`` from ``picked_columns``."""
    return _checked_draw(a, metrics, path, f'the trajectory of {path.parent}')


def write_summary(out_dir: pathlib.Path, stop: StopRequest | None = None) -> pathlib.Path:
    """Draw ``out_dir/summary.png`` from ``out_dir/trajectory.npz`` and ``metrics.json``, whole
    or not at all (drawn under a hidden name, renamed when complete).

    :param stop: looked for before the reading, the drawing and the renaming.
    :return: the path of the PNG.
    :raises InputRefused: when a file is missing, lacks a column or holds no sample.
    :raises RunInterrupted: on a stop signal (the picture is then not written).
    """
    out_dir = pathlib.Path(out_dir)
    missing = [name for name in ('trajectory.npz', 'metrics.json')
               if not (out_dir / name).is_file()]
    if missing:
        raise InputRefused(f'no run summary: {", ".join(missing)} missing in {out_dir}')
    trajectory = out_dir / 'trajectory.npz'
    raise_if_stopped(stop)
    try:
        metrics = json.loads((out_dir / 'metrics.json').read_text(encoding='utf-8'))
        with np.load(trajectory) as npz:
            a = {key: npz[key] for key in DRAWN_COLUMNS if key in npz.files and key != 'q'}
            if 'q' in npz.files:
                a['shoulders'] = _shoulders(trajectory)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:  # damaged
        raise InputRefused(f'cannot read the run in {out_dir}: {type(exc).__name__}: '
                           f'{exc}') from None
    with StagedFiles(out_dir) as staged:
        raise_if_stopped(stop)
        _checked_draw(a, metrics, staged(SUMMARY_NAME), str(trajectory))
        raise_if_stopped(stop)
        (path,) = staged.commit()
    return path


def main(argv: list[str] | None = None) -> int:
    """Console entry point ``summary DIR``: exit 0 (the picture's path on stdout), 2 (the run
    refused) or 1 (the picture not written) with one line on stderr saying why, or 128 + the
    number of a stop signal with one line (``iceskate_sim.exit_codes``)."""
    with StopRequest() as stop:  # before the imports of the model and matplotlib (about 1 s)
        return _main(argv, stop)


def _main(argv: list[str] | None, stop: StopRequest) -> int:
    parser = argparse.ArgumentParser(
        prog='summary', description="Draw DIR/summary.png from a finished run's "
        'trajectory.npz and metrics.json (e.g. of the nodes run by hand, which draw none).')
    parser.add_argument('dir', type=pathlib.Path, help='output folder of a run')
    args = parser.parse_args(argv)
    try:
        path = write_summary(args.dir, stop)
    except RunInterrupted as exc:
        say(f'summary: interrupted by {signal.Signals(exc.signum).name}; '
            f'{args.dir / SUMMARY_NAME} not written')
        return exc.exit_code
    except SimulationError as exc:
        return error_exit('summary', exc)
    except OSError as exc:  # the picture cannot be written
        return error_exit('summary', exc,
                          f'cannot write {args.dir / SUMMARY_NAME}: {exc.strerror or exc}')
    print(path, flush=True)
    return DONE



def _checked_draw(a: dict[str, np.ndarray], metrics: Mapping[str, Any], path: pathlib.Path,
                  source: str) -> pathlib.Path:
    """``_draw`` once ``a`` (``shoulders`` for q) has every column and a sample."""
    absent = [key for key in DRAWN_COLUMNS
              if key not in a and (key != 'q' or 'shoulders' not in a)]
    if absent:
        raise InputRefused(f'{source} lacks the column(s) {absent}')
    if a['t'].size == 0:
        raise InputRefused(f'{source} holds no sample')
    _draw(a, metrics, path)
    return path


def _shoulders(path: pathlib.Path, chunk: int = 65536) -> np.ndarray:
    """Columns q11 and q14 of ``path``'s q, (n, 2), read ``chunk`` rows at a time (q of a
    600 s run holds 86 MB; the picture needs 2/18 of it)."""
    from iceskate_sim.run.metrics import SHOULDERS
    with zipfile.ZipFile(path) as archive, archive.open('q.npy') as stream:
        version = np.lib.format.read_magic(stream)
        read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                       else np.lib.format.read_array_header_2_0)
        shape, fortran, dtype = read_header(stream)
        if fortran or len(shape) != 2 or shape[1] != 18:
            raise InputRefused(f'{path} holds a q of shape {shape}; the summary needs '
                               '(n, 18) in C order')
        out = np.zeros((shape[0], 2))
        for start in range(0, shape[0], chunk):
            rows = min(chunk, shape[0] - start)
            block = np.frombuffer(stream.read(rows * shape[1] * dtype.itemsize), dtype=dtype)
            out[start:start + rows] = block.reshape(rows, shape[1])[:, list(SHOULDERS)]
    return out


def _draw(a: dict[str, np.ndarray], metrics: dict[str, Any], path: pathlib.Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    from iceskate_analysis.plots import clip_to_bulk, legend_above
    from iceskate_sim.run.metrics import ARM_SWING_FROM_STEP

    t, psi, psi_d = a['t'], a['psi'], a['head_target']
    steps = a['step_index']
    exchanges = t[np.flatnonzero(np.diff(steps) != 0) + 1]
    rms = metrics.get('head_error_rms') or {}
    height = 13.6  # inches; the two title lines take the top 0.7
    fig = Figure(figsize=(10.0, height),
                 layout=ConstrainedLayoutEngine(rect=(0.0, 0.0, 1.0, 1.0 - 0.7 / height)))
    FigureCanvasAgg(fig)
    axes = fig.subplots(6, 1, sharex=True,
                        gridspec_kw={'height_ratios': (1, 1, 1, 1.35, 1, 1)})
    head, failure = _title(metrics, t)
    fig.text(0.015, 1.0 - 0.15 / height, head, fontsize=11, weight='bold', va='top')
    fig.text(0.015, 1.0 - 0.4 / height, failure, fontsize=9, va='top',
             color='darkgreen' if metrics.get('failure') is None else 'firebrick')

    _tracking(axes[0], t, psi[:, 0], psi_d[:, 0], 'target y_d', color='tab:green', lw=1.1,
              label='head y' + _rms(rms, 'y', 1e2, 'cm'))
    axes[0].set_ylabel('head forward position\ny [m]')
    _tracking(axes[1], t, psi[:, 1], psi_d[:, 1], 'target z_d', color='tab:blue', lw=1.1,
              label='head z' + _rms(rms, 'z', 1e3, 'mm'))
    axes[1].set_ylabel('head height z [m]')
    axes[1].ticklabel_format(axis='y', useOffset=False)
    _tracking(axes[2], t, np.degrees(psi[:, 2]), np.degrees(psi_d[:, 2]), 'target',
              color='tab:purple', lw=1.0,
              label='head pitch' + _rms(rms, 'pitch', np.degrees(1.0), 'deg'))
    axes[2].set_ylabel('head pitch [deg]')

    _mode_panel(axes[3], t, a['mode'], a['side'], exchanges)

    ax = axes[4]
    q11, q14 = np.degrees(a['shoulders']).T
    _line(ax, t, q11, color='tab:red', lw=1.4, label='q11 right shoulder')
    _line(ax, t, q14, color='tab:blue', lw=1.1, label='q14 left shoulder')
    late = np.flatnonzero(steps >= ARM_SWING_FROM_STEP)
    if late.size and late[0] > 0:
        ax.axvline(t[late[0]], color='k', lw=1.0, ls='--', label='4th step (arm-swing window)')
    ax.set_ylabel('shoulder angle [deg]')
    clip_to_bulk(ax, (q11, q14), **_DIVERGENCE)

    ax = axes[5]
    if t.size >= 2:
        _tracking(ax, t, np.gradient(psi[:, 0], t), np.gradient(psi_d[:, 0], t),
                  'target dy_d/dt', color='tab:green', lw=1.0, label='head dy/dt')
        if t[-1] > t[0]:
            mean = (psi[-1, 0] - psi[0, 0]) / (t[-1] - t[0])
            ax.axhline(mean, color='darkgreen', lw=0.9, ls=':',
                       label=f'mean {round(mean, 2) + 0.0:.2f} m/s')  # + 0.0: no '-0.00'
    ax.set_ylabel('forward speed\nd(head y)/dt [m/s]')
    ax.set_xlabel('time t [s]')

    for ax in axes:
        if exchanges.size:
            ax.vlines(exchanges, 0.0, 1.0, transform=ax.get_xaxis_transform(), colors='0.65',
                      lw=0.6, linestyles=':', zorder=0)
        if ax is not axes[3]:  # the mode panel has its own grid, legend and key
            ax.grid(True, axis='y', color='0.9', lw=0.6)
            legend_above(ax)
        ax.tick_params(labelsize=8)
        ax.yaxis.label.set_size(9)
    axes[-1].set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1e-3)
    fig.align_ylabels(axes)
    fig.savefig(path, dpi=_DPI)


def _rms(rms: dict[str, float], key: str, scale: float, unit: str) -> str:
    value = rms.get(key)
    return f' (error RMS {value * scale:.3g} {unit})' if value is not None else ''


def _title(metrics: dict[str, Any], t: np.ndarray) -> tuple[str, str]:
    """The two title lines: what ran, and how it ended."""
    duration = metrics.get('sim_time_s', float(t[-1] - t[0]))
    scene, steps = metrics.get('scene', '?'), metrics.get('steps', '?')
    head = f'{scene}: {duration:.2f} s simulated, {steps} step{"" if steps == 1 else "s"}'
    distance = metrics.get('forward_distance_m')
    if distance is not None:
        head += f', {round(distance, 2) + 0.0:.2f} m forward (head y)'
    rtf = metrics.get('real_time_factor')
    rtf_text = (f' (real-time factor {rtf:.2f})'
                if isinstance(rtf, int | float) and np.isfinite(rtf) else '')
    if metrics.get('failure') is None:
        return head, 'no fall, no failure' + rtf_text
    failure = ' '.join(str(metrics['failure']).split())
    what = {'fell': 'FELL', 'interrupted': 'INTERRUPTED'}.get(metrics.get('end'), 'FAILED')
    return head, textwrap.shorten(f'{what}: {failure}', 170, placeholder=' …')


def _decimate(t: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS
              ) -> tuple[np.ndarray, np.ndarray]:
    """At most ~``max_points`` samples of (t, y): the min and the max of each bucket, in time
    order (a plot of them looks like the full series at figure resolution)."""
    n = t.size
    if n <= max_points:
        return t, y
    size = int(np.ceil(2 * n / max_points))
    m = n // size
    body = y[:m * size].reshape(m, size)
    offsets = np.arange(m) * size
    lo = offsets + np.argmin(body, axis=1)
    hi = offsets + np.argmax(body, axis=1)
    keep = np.unique(np.concatenate([lo, hi, np.arange(m * size, n), [0, n - 1]]))  # sorted
    return t[keep], y[keep]


def _line(ax: Axes, t: np.ndarray, y: np.ndarray, **style: Any) -> None:
    ax.plot(*_decimate(t, np.asarray(y, dtype=float)), **style)


def _tracking(ax: Axes, t: np.ndarray, y: np.ndarray, target: np.ndarray, target_label: str,
              **style: Any) -> None:
    """``y`` (drawn with ``style``) against its ``target`` (dashed black), y range clipped
    only for a blow-up."""
    from iceskate_analysis.plots import clip_to_bulk
    _line(ax, t, y, **style)
    _line(ax, t, target, color='k', lw=1.0, ls='--', label=target_label)
    clip_to_bulk(ax, (y, target), **_DIVERGENCE)


def _mode_panel(ax: Axes, t: np.ndarray, mode: np.ndarray, side: np.ndarray,
                exchanges: np.ndarray) -> None:
    """Gait mode as a step plot from its change points; left-support spans shaded, exchanges
    marked by triangles along the top; the swing-foot state of each band of 4 on the right;
    the legend above, the key of the states above it."""
    from iceskate_analysis.plots import legend_above
    end = t[-1] + (t[-1] - t[-2] if t.size >= 2 else 1e-3)
    changes = np.flatnonzero(np.diff(mode) != 0) + 1
    starts = np.concatenate([[0], changes])
    ax.step(np.append(t[starts], end), np.append(mode[starts], mode[-1]), where='post',
            color='tab:orange', lw=1.3, label='gait mode')
    left = (side == 1).astype(np.int8)
    if left.any():
        ax.fill_between(np.append(t, end), 0.0, 1.0, where=np.append(left, left[-1]) > 0,
                        step='post', transform=ax.get_xaxis_transform(), color='tab:blue',
                        alpha=0.08, lw=0, label='support on the left foot')
    if exchanges.size:
        ax.plot(exchanges, np.full(exchanges.size, 20.9), 'v', color='0.3', ms=4,
                label=f'support exchange ({exchanges.size})')
    ax.set_ylim(0.4, 21.4)
    visited = set(mode.tolist()) | {1, 20}
    ax.set_yticks(range(1, 21), [str(m) if m in visited else '' for m in range(1, 21)])
    ax.tick_params(axis='y', labelsize=7)
    for m, code in _SWING_GROUPS:
        if m > 1:
            ax.axhline(m - 0.5, color='0.8', lw=0.6, zorder=0)
        ax.text(1.006, m + 1.5, code, transform=ax.get_yaxis_transform(), fontsize=7.5,
                color='0.35', va='center', ha='left')
    ax.set_ylabel('gait mode [no. 1-20]\n(labelled: visited)')
    legend_above(ax, title=_SWING_KEY, loc='left', fontsize=7, color='0.35')


if __name__ == '__main__':
    sys.exit(main())
