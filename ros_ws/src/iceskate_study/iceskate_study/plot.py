"""Heat maps of a sweep's table: ``sweep-plot DIR --x KEY --y KEY --metric NAME``.

One PNG per metric, ``DIR/maps/<metric>.png``: a grid sweep as cells (the mean over the runs at
each (x, y), written in the cell; grid axes evenly spaced by index), a sampled one as coloured
points; the axes and the colour bar say their key or metric, its unit and its meaning.
"""

from __future__ import annotations

import argparse
from collections.abc import Collection, Sequence
import math
import pathlib
import re
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.run.metrics import METRICS
from iceskate_study.errors import StudyError, StudyRefused
from iceskate_study.table import RESULTS, read_table

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: The maps drawn when neither the command nor the SPEC names any (those the table has).
DEFAULT_METRICS = ('steps', 'fell', 'forward_distance_m', 'arm_swing_ratio',
                   'arm_swing_steady.corr_q11_q14')
_MAX_ANNOTATED = 400  # cells: values are written in the cells of grids up to this size
_PAD = 0.08  # [inch] kept clear around the figure's labels
_CELL_DIGITS = (3, 6)  # significant digits of a cell's value: at least, at most


def _label(value: Any) -> str:
    return f'{value:.3g}' if isinstance(value, float) else str(value)


def cell_text(value: float) -> str:
    """A cell's value at 3 significant digits, more (up to 6) where those would print a value
    that is not a whole number as one (-0.9996: '-0.9996', not '-1'; 999.6: '999.6')."""
    low, high = _CELL_DIGITS
    whole = float(value).is_integer()
    for digits in range(low, high + 1):
        text = f'{value:.{digits}g}'
        if whole or not float(text).is_integer():
            break
    return text


def metric_label(metric: str, ratios: Collection[str] = ()) -> str:
    """A colour bar's label: the metric's column, its unit and, below, its meaning, from the
    metrics' registry (``METRICS``); a ratio of the table none registers: '×'; else the column
    alone."""
    known = METRICS.get(metric)
    if known is not None:
        unit, meaning = known.unit, known.label
    elif metric in ratios:
        unit, meaning = '×', 'ratio against the baseline run'
    else:
        return metric
    return f'{metric} [{unit}]\n{meaning}' if unit else f'{metric}\n{meaning}'


def axis_label(key: str) -> str:
    """A map's axis label: the scene key, its unit and, below, its description, from the
    schema that declares it (the key alone where none does)."""
    from iceskate_bringup.scene import key_rules
    rules = key_rules(key)
    if rules is None:
        return key
    text = rules.description if len(rules.description) <= 60 else rules.description[:57] + '...'
    return f'{key} [{rules.unit or "-"}]\n{text}'


def _numbers(values: list[Any]) -> np.ndarray:
    """Floats of a column (booleans as 0/1, missing as NaN)."""
    return np.array([float(v) if isinstance(v, (bool, int, float)) else math.nan for v in values])


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


def draw_maps(table_path: pathlib.Path, x: str | None, y: str | None,
              metrics: Sequence[str] | None, out_dir: pathlib.Path) -> list[pathlib.Path]:
    """Draw one heat map per metric of the table at ``table_path`` over axes ``x`` and ``y``
    into ``out_dir``; the files written. None: the SPEC's maps, else the first two axes and
    DEFAULT_METRICS.

    :raises StudyRefused: a table that cannot be read, an unknown axis or metric.
    :raises StudyError: an output folder that cannot be made.
    """
    table, meta = read_table(table_path)
    axes, maps, columns = meta.get('axes', {}), meta.get('maps') or {}, table.column_names
    x = x or maps.get('x') or next(iter(axes), '')
    y = y or maps.get('y') or (list(axes)[1] if len(axes) > 1 else '')
    if not y:
        raise StudyRefused(f'{table_path} has one axis ({x}): a map needs two')
    metrics = metrics or maps.get('metrics') or [m for m in DEFAULT_METRICS if m in columns]
    for name, what in ((x, '--x'), (y, '--y')):
        if name not in axes:
            raise StudyRefused(f'{what} {name!r} is not an axis of {table_path}; its axes: '
                               f'{list(axes)}')
    declared = [*meta.get('ratios', {}), *meta.get('metrics', [])]
    for metric in metrics:  # a metric the SPEC keeps may have no value in any run yet
        known = metric in declared or any(metric.startswith(f'{m}.') for m in declared)
        if metric not in columns and not known:
            numeric = [c for c in columns if c not in axes and c not in ('key', 'failure',
                                                                        'run_dir', 'status')]
            raise StudyRefused(f'--metric {metric!r} is not a column of {table_path}; its '
                               f'metrics: {numeric}')
    if table.num_rows == 0:
        raise StudyRefused(f'{table_path} has no rows yet')
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StudyError(f'cannot create {out_dir}: {exc.strerror or exc}') from None
    written = []
    for metric in metrics:
        fig = map_figure(table, meta, x, y, metric)
        path = out_dir / (re.sub(r'[^A-Za-z0-9_.-]', '_', metric) + '.png')
        fig.savefig(path)
        written.append(path)
    return written


def map_figure(table: Any, meta: dict[str, Any], x: str, y: str, metric: str) -> Figure:
    """The heat map of column ``metric`` of ``table`` (a ``pyarrow.Table`` with the metadata
    ``meta`` of ``read_table``) over its axes ``x`` and ``y``: cells for a grid sweep, points
    for a sampled one; NaN where the table has no such column. Laid out (constrained) so that
    every label lies inside the figure."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    axes = meta.get('axes', {})
    xs, ys = table.column(x).to_pylist(), table.column(y).to_pylist()
    values = (_numbers(table.column(metric).to_pylist()) if metric in table.column_names
              else np.full(table.num_rows, np.nan))
    fig = Figure(figsize=(7.0, 5.2), dpi=100, layout='constrained')
    fig.get_layout_engine().set(w_pad=_PAD, h_pad=_PAD)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    cmap, low, high = (('coolwarm', -1.0, 1.0) if 'corr' in metric else
                       ('Reds', 0.0, 1.0) if metric == 'fell' else ('viridis', None, None))
    style = {'cmap': matplotlib.colormaps[cmap].with_extremes(bad='0.85'), 'vmin': low,
             'vmax': high}
    if meta.get('sampling', 'grid') == 'grid':
        image, per_cell = _grid(ax, xs, ys, values, style)
    else:  # a coloured point per run, a grey cross where the run has no value
        ok, px, py = np.isfinite(values), _numbers(xs), _numbers(ys)
        image = ax.scatter(px[ok], py[ok], c=values[ok], s=36, edgecolors='none', **style)
        ax.scatter(px[~ok], py[~ok], marker='x', color='0.5', s=24)
        per_cell = 1
        ax.set_xscale('log' if axes[x].get('log') else 'linear')
        ax.set_yscale('log' if axes[y].get('log') else 'linear')
    bar = fig.colorbar(image, ax=ax)
    bar.set_label(metric_label(metric, meta.get('ratios', {})), fontsize=9)
    ax.set_xlabel(axis_label(x), fontsize=9)
    ax.set_ylabel(axis_label(y), fontsize=9)
    note = f' (mean of {per_cell} runs per cell)' if per_cell > 1 else ''
    ax.set_title(f'{meta.get("study", "sweep")}: {metric}{note}', fontsize=10)
    if ax.texts:
        _fit_cells(fig, ax)
    return fig


def _fit_cells(fig: Figure, ax: Any) -> None:
    """Shrink the values written in the cells of ``ax`` (all alike) until the widest takes at
    most 90 % of a cell's width, measured on the laid-out figure."""
    fig.draw_without_rendering()
    renderer = fig.canvas.get_renderer()
    cell = ax.get_window_extent(renderer).width / ax.images[0].get_array().shape[1]  # [px]
    widest = max(text.get_window_extent(renderer).width for text in ax.texts)  # [px]
    if widest > 0.9 * cell:
        for text in ax.texts:
            text.set_fontsize(text.get_fontsize() * 0.9 * cell / widest)


def _grid(ax: Any, xs: list[Any], ys: list[Any], values: np.ndarray, style: dict[str, Any]
          ) -> tuple[Any, int]:
    """A cell per (x, y) value pair: the mean of ``values`` (grey: none); the image and the
    most runs in a cell."""
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
    image = ax.imshow(np.ma.masked_invalid(mean), origin='lower', aspect='auto',
                      interpolation='nearest', **style)
    ax.set_xticks(range(len(col)), [_label(v) for v in col],
                  rotation=45 if len(col) > 6 else 0)
    ax.set_yticks(range(len(row)), [_label(v) for v in row])
    if mean.size <= _MAX_ANNOTATED:
        finite = mean[np.isfinite(mean)]
        middle = (float(np.min(finite)) + float(np.max(finite))) / 2 if finite.size else 0.0
        for i in range(len(row)):
            for j in range(len(col)):
                text = (cell_text(mean[i, j]) if counts[i, j] else
                        'failed' if runs[i, j] else '')
                dark = style['cmap'].name == 'viridis' and counts[i, j] and mean[i, j] < middle
                ax.text(j, i, text, ha='center', va='center', fontsize=8,
                        color='white' if dark else 'black')
    return image, int(runs.max()) if runs.size else 0


def main(argv: list[str] | None = None) -> int:
    """Console entry point: draw the maps; exit 2 when refused, 1 when the folder of the maps
    cannot be made, with one line (``iceskate_sim.exit_codes``)."""
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
            raise StudyRefused(f'{path} does not exist: give the --out folder of a sweep')
        written = draw_maps(path, args.x, args.y, args.metric, args.out or path.parent / 'maps')
    except StudyError as exc:
        return error_exit('sweep-plot', exc)
    for p in written:
        print(p)
    return DONE


if __name__ == '__main__':
    sys.exit(main())
