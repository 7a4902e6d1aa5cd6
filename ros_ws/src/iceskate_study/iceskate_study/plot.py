"""Heat maps of a sweep's table: ``sweep-plot DIR --x KEY --y KEY --metric NAME``.

One PNG per metric, ``DIR/maps/<metric>.png``: over a grid, each cell is the mean of the metric
over the runs at that (x, y) (the repeats, and the other axes' values, averaged; the count is
in the title when it is above 1), with its value written in it; cells without a value (every
run failed there) are grey. ``fell`` is drawn as the fraction of runs that fell. Sampled sweeps
(random, Latin hypercube) are drawn as coloured points. Grid axes are evenly spaced by index,
labelled with their values (a logspace axis then reads as a log scale). Reads only the table
(``iceskate_study.table``); matplotlib (Agg) is imported on the first call.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import re
import sys
from typing import Any

import numpy as np

from iceskate_sim.shutdown import say
from iceskate_study.errors import StudyError
from iceskate_study.table import RESULTS, read_table

#: Colour-bar labels of the usual metrics (others: their name).
LABELS = {
    'steps': 'support exchanges',
    'fell': 'fraction of runs that fell',
    'forward_distance_m': 'forward distance of the head [m]',
    'arm_swing_ratio': 'arm swing over the swing without yaw [-]',
    'arm_swing_steady.corr_q11_q14': 'corr(q11, q14), second half from the 4th step [-]',
    'arm_swing.corr_q11_q14': 'corr(q11, q14) from the 4th step [-]',
    'arm_swing_steady.q11_peak_to_peak': 'q11 peak to peak, steady [rad]',
    'arm_swing_steady.q14_peak_to_peak': 'q14 peak to peak, steady [rad]',
}
_CMAPS = {'fell': ('Reds', 0.0, 1.0)}
_MAX_ANNOTATED = 400  # cells: values are written in the cells of grids up to this size


def _label(value: Any) -> str:
    return f'{value:.4g}' if isinstance(value, float) else str(value)


def _numbers(values: list[Any]) -> np.ndarray:
    """Floats of a column (booleans as 0/1, missing as NaN)."""
    out = np.full(len(values), np.nan)
    for i, v in enumerate(values):
        if isinstance(v, (bool, int, float)) and not (isinstance(v, float) and math.isnan(v)):
            out[i] = float(v)
    return out


def _hashable(value: Any) -> Any:
    """``value`` with its lists as tuples (a vector-valued axis, e.g. a gain vector)."""
    return tuple(map(_hashable, value)) if isinstance(value, list) else value


def _ordered(values: list[Any]) -> list[Any]:
    """The distinct values but None, sorted where they compare (lists by their entries)."""
    unique = list({_hashable(v): v for v in values if v is not None}.values())
    try:
        return sorted(unique)
    except TypeError:
        return unique


def file_name(metric: str) -> str:
    """The PNG's name of a metric."""
    return re.sub(r'[^A-Za-z0-9_.-]', '_', metric) + '.png'


def draw_maps(table_path: pathlib.Path, x: str, y: str, metrics: tuple[str, ...] | list[str],
              out_dir: pathlib.Path) -> list[pathlib.Path]:
    """Draw one heat map per metric of the table at ``table_path`` over axes ``x`` and ``y``
    into ``out_dir``; the files written.

    :raises StudyError: a table that cannot be read, an unknown axis or metric.
    """
    table, meta = read_table(table_path)
    axes = meta.get('axes', {})
    for name, what in ((x, '--x'), (y, '--y')):
        if name not in axes:
            raise StudyError(f'{what} {name!r} is not an axis of {table_path}; its axes: '
                             f'{list(axes)}')
    columns = table.column_names
    declared = [*meta.get('ratios', {}), *meta.get('metrics', [])]
    for metric in metrics:  # a metric the SPEC keeps may have no value in any run yet
        known = metric in declared or any(metric.startswith(f'{m}.') for m in declared)
        if metric not in columns and not known:
            numeric = [c for c in columns if c not in axes and c not in ('key', 'failure',
                                                                        'run_dir', 'status')]
            raise StudyError(f'--metric {metric!r} is not a column of {table_path}; its '
                             f'metrics: {numeric}')
    if table.num_rows == 0:
        raise StudyError(f'{table_path} has no rows yet')
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StudyError(f'cannot create {out_dir}: {exc.strerror or exc}') from None
    from matplotlib.figure import Figure
    xs, ys = table.column(x).to_pylist(), table.column(y).to_pylist()
    grid = meta.get('sampling', 'grid') == 'grid'
    written = []
    for metric in metrics:
        values = (_numbers(table.column(metric).to_pylist()) if metric in columns
                  else np.full(table.num_rows, np.nan))
        fig = Figure(figsize=(7.0, 5.2), dpi=100, layout='constrained')
        ax = fig.add_subplot()
        cmap, low, high = _CMAPS.get(metric, ('viridis', None, None))
        if 'corr' in metric:
            cmap, low, high = 'coolwarm', -1.0, 1.0
        if grid:
            per_cell = _grid(ax, fig, xs, ys, values, cmap, low, high, metric)
        else:
            per_cell = 1
            _scatter(ax, fig, xs, ys, values, cmap, low, high, metric,
                     axes[x].get('log', False), axes[y].get('log', False))
        ax.set_xlabel(x)
        ax.set_ylabel(y)
        note = f' (mean of {per_cell} runs per cell)' if per_cell > 1 else ''
        ax.set_title(f'{meta.get("study", "sweep")}: {metric}{note}', fontsize=10)
        path = out_dir / file_name(metric)
        fig.savefig(path)
        written.append(path)
    return written


def _grid(ax: Any, fig: Any, xs: list[Any], ys: list[Any], values: np.ndarray, cmap: str,
          low: float | None, high: float | None, metric: str) -> int:
    """A cell per (x, y) value pair: the mean of ``values``; the most runs in a cell."""
    col, row = _ordered(xs), _ordered(ys)
    sums = np.zeros((len(row), len(col)))
    counts = np.zeros((len(row), len(col)), dtype=int)
    runs = np.zeros((len(row), len(col)), dtype=int)
    for xv, yv, value in zip(xs, ys, values, strict=True):
        if xv is None or yv is None:
            continue
        i, j = row.index(yv), col.index(xv)
        runs[i, j] += 1
        if not math.isnan(value):
            sums[i, j] += value
            counts[i, j] += 1
    mean = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    masked = np.ma.masked_invalid(mean)
    import matplotlib
    colours = matplotlib.colormaps[cmap].with_extremes(bad='0.85')
    image = ax.imshow(masked, origin='lower', aspect='auto', cmap=colours, vmin=low, vmax=high,
                      interpolation='nearest')
    fig.colorbar(image, ax=ax, label=LABELS.get(metric, metric))
    ax.set_xticks(range(len(col)), [_label(v) for v in col],
                  rotation=45 if len(col) > 6 else 0)
    ax.set_yticks(range(len(row)), [_label(v) for v in row])
    if mean.size <= _MAX_ANNOTATED:
        finite = mean[np.isfinite(mean)]
        middle = (float(np.min(finite)) + float(np.max(finite))) / 2 if finite.size else 0.0
        for i in range(len(row)):
            for j in range(len(col)):
                text = f'{mean[i, j]:.2g}' if counts[i, j] else ('failed' if runs[i, j] else '')
                dark = cmap in ('viridis',) and counts[i, j] and mean[i, j] < middle
                ax.text(j, i, text, ha='center', va='center', fontsize=8,
                        color='white' if dark else 'black')
    return int(runs.max()) if runs.size else 0


def _scatter(ax: Any, fig: Any, xs: list[Any], ys: list[Any], values: np.ndarray, cmap: str,
             low: float | None, high: float | None, metric: str, log_x: bool,
             log_y: bool) -> None:
    """One coloured point per run (a grey cross where the run has no value)."""
    x, y = _numbers(xs), _numbers(ys)
    ok = np.isfinite(values)
    points = ax.scatter(x[ok], y[ok], c=values[ok], cmap=cmap, vmin=low, vmax=high, s=36,
                        edgecolors='none')
    ax.scatter(x[~ok], y[~ok], marker='x', color='0.5', s=24)
    fig.colorbar(points, ax=ax, label=LABELS.get(metric, metric))
    if log_x:
        ax.set_xscale('log')
    if log_y:
        ax.set_yscale('log')


def main(argv: list[str] | None = None) -> int:
    """Console entry point: draw the maps; exit 1 (one line) when refused."""
    parser = argparse.ArgumentParser(prog='sweep-plot', description=__doc__.split('\n\n')[0])
    parser.add_argument('dir', type=pathlib.Path, help="a sweep's output directory (or its "
                                                       'results.parquet)')
    parser.add_argument('--x', help='axis along x (default: the first axis)')
    parser.add_argument('--y', help='axis along y (default: the second axis)')
    parser.add_argument('--metric', action='append', metavar='NAME',
                        help="a column to map (repeatable; default: the SPEC's maps, else "
                             'steps, fell, forward distance, arm-swing ratio, corr(q11, q14))')
    parser.add_argument('--out', type=pathlib.Path, help='folder for the PNGs (default: '
                                                         'DIR/maps)')
    args = parser.parse_args(argv)
    path = args.dir if args.dir.suffix == '.parquet' else args.dir / RESULTS
    try:
        if not path.is_file():
            raise StudyError(f'{path} does not exist: give the --out folder of a sweep')
        _table, meta = read_table(path)
        axes = list(meta.get('axes', {}))
        maps = meta.get('maps') or {}
        x = args.x or maps.get('x') or (axes[0] if axes else '')
        y = args.y or maps.get('y') or (axes[1] if len(axes) > 1 else '')
        if not y:
            raise StudyError(f'{path} has one axis ({axes[0]}): a map needs two')
        columns = _table.column_names
        metrics = args.metric or maps.get('metrics') or [
            m for m in ('steps', 'fell', 'forward_distance_m', 'arm_swing_ratio',
                        'arm_swing_steady.corr_q11_q14') if m in columns]
        written = draw_maps(path, x, y, metrics, args.out or path.parent / 'maps')
    except StudyError as exc:
        say(f'sweep-plot: error: {exc}')
        return 1
    for p in written:
        print(p)
    return 0


if __name__ == '__main__':
    sys.exit(main())
