"""The paper's Figs. 3 and 5-8 from analysed runs as PNG (matplotlib, Agg; no pyplot state):
the visited gait-transition diagram (Fig. 3), shoulder angles (Figs. 5/6), the terms of eq. (11)
at a joint (Figs. 7/8) and the largest coupling terms.
"""

from __future__ import annotations

from collections.abc import Sequence
import pathlib
from typing import TYPE_CHECKING, Any

import numpy as np

from iceskate_sim.model.robot import COORDINATE_NAMES

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from iceskate_analysis.coupling import CaseResult, JointDecomposition
    from iceskate_analysis.coverage import Coverage

__all__ = ['plot_compare_shoulders', 'plot_coupling', 'plot_mode_coverage', 'plot_shoulders',
           'plot_terms']

_DPI = 110


def _figure(rows: int, height: float = 2.6, width: float = 9.0, sharey: bool = False,
            ) -> tuple[Figure, list[Axes]]:
    """``rows`` panels one above the other sharing the time axis (and the y axis if
    ``sharey``), each ``height`` inches high, on an Agg canvas (``legend_above`` measures)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width, 0.6 + height * rows), layout='constrained')
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, sharex=True, sharey=sharey, squeeze=False)[:, 0]
    return fig, list(axes)


def _save(fig: Figure, path: str | pathlib.Path) -> pathlib.Path:
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=_DPI)
    return path


def legend_above(ax: Axes, ncol: int = 4, title: str = '', **title_style: Any) -> None:
    """The legend of ``ax`` just above it, right-aligned, off the data, in rows of ``ncol``
    entries (fewer if the rows would be wider than the axes; no legend without a labelled line,
    e.g. a run ended at its first instant), and ``title`` (``Axes.set_title`` with
    ``title_style``) above the legend, however many rows it has. Call it once every labelled
    line is drawn; the figure needs an Agg canvas (it measures the legend)."""
    fig = ax.get_figure()
    renderer = fig.canvas.get_renderer()
    size, gap = 7.5, 0.2  # the legend's font [pt]; its gap to the axes [font sizes]
    room = 0.0  # [pt] the legend takes above the axes
    for columns in range(min(ncol, len(ax.get_legend_handles_labels()[0])), 0, -1):
        legend = ax.legend(loc='lower right', bbox_to_anchor=(1.0, 1.0), ncol=columns,
                           fontsize=size, frameon=False, borderaxespad=gap, handlelength=2.2)
        box = legend.get_window_extent(renderer)  # pixels
        room = box.height * 72.0 / fig.dpi + gap * size
        if box.width <= ax.get_window_extent(renderer).width:
            break
    if title:
        from matplotlib import rcParams
        ax.set_title(title, pad=rcParams['axes.titlepad'] + room, **title_style)


def clip_to_bulk(ax: Axes, series: Sequence[np.ndarray], percentile: float = 2.0,
                 margin: float = 0.5, reach: float = 0.5, note: str = '') -> None:
    """Clip the y range of ``ax`` to the bulk of the data when a few samples (a fall, a
    divergence) dwarf it: the bulk is the ``percentile``..(100 - ``percentile``) range of the
    finite values; the y range becomes the bulk widened by ``margin`` times its span, if some
    value lies more than ``reach`` spans beyond it; a note in the corner says so (``note``
    appended)."""
    values = np.concatenate([np.asarray(x, dtype=float).ravel() for x in series])
    values = values[np.isfinite(values)]
    if values.size < 20:
        return
    lo, hi = np.percentile(values, [percentile, 100.0 - percentile])
    span = hi - lo if hi > lo else max(1e-9, 0.2 * abs(hi))
    if values.min() < lo - reach * span or values.max() > hi + reach * span:
        ax.set_ylim(lo - margin * span, hi + margin * span)
        ax.text(0.01, 0.02, f'y range clipped (data span {values.min():.3g} to '
                f'{values.max():.3g}{note})', transform=ax.transAxes, fontsize=7,
                color='0.35', va='bottom')


def _index(name: str) -> str:
    """Subscript of a coordinate name: 'q11' -> '11', 'y0' -> 'y0'."""
    return name if name == 'y0' else name[1:]


def _mark_steps(ax: Axes, case: CaseResult, legend: bool = True) -> None:
    """Dotted lines at every support exchange, a bold one at the 4th step."""
    bag = case.kept
    changes = np.flatnonzero(np.diff(bag.step_index) != 0) + 1
    for k in changes:
        ax.axvline(bag.t[k], color='0.75', lw=0.6, ls=':', zorder=0)
    fourth = case.fourth_step_s
    if fourth is not None:
        ax.axvline(fourth, color='k', lw=1.2, ls='--', label='4th step' if legend else None)


def _shoulder_lines(ax: Axes, case: CaseResult, lw: float, title: str, label: str = '',
                    **title_style: Any) -> None:
    """q11 (right) and q14 (left shoulder) [deg] against time, the steps marked, the legend
    and ``title`` above."""
    for joint, colour, side in ((11, 'tab:red', 'right'), (14, 'tab:blue', 'left')):
        ax.plot(case.kept.t, np.degrees(case.kept.q[:, joint]), color=colour, lw=lw,
                label=f'q{joint} {side}{label}')
    _mark_steps(ax, case)
    ax.grid(True, alpha=0.3)
    legend_above(ax, title=title, **title_style)


def plot_shoulders(case: CaseResult, path: str | pathlib.Path, title: str | None = None,
                   ) -> pathlib.Path:
    """Figs. 5/6: q11 (right) and q14 (left shoulder) against time [deg]."""
    fig, (ax,) = _figure(1, height=3.4)
    _shoulder_lines(ax, case, 1.3, title or f'{case.label}: shoulder angles', ' shoulder')
    arms = case.arms
    ax.set_xlabel('time [s]')
    ax.set_ylabel('joint angle [deg]')
    ax.text(0.01, 0.02, f'from {"step 4" if arms.window_from_step is not None else "start"}: '
            f'p-p q11 {np.degrees(arms.peak_to_peak["q11"]):.2f}°, '
            f'q14 {np.degrees(arms.peak_to_peak["q14"]):.2f}°, '
            f'corr {arms.correlation:.2f}, phase {arms.phase_difference_deg:.0f}°',
            transform=ax.transAxes, fontsize=8, va='bottom')
    return _save(fig, path)


def plot_compare_shoulders(cases: list[CaseResult], path: str | pathlib.Path,
                           ) -> pathlib.Path:
    """Both cases' shoulder angles one above the other, on the same time and angle scales."""
    fig, axes = _figure(len(cases), height=2.8, sharey=True)
    for ax, case in zip(axes, cases, strict=True):
        yaw = 'with' if case.torso_yaw_input else 'without'
        _shoulder_lines(ax, case, 1.2, f'{case.label} ({yaw} torso-yaw input τ8)',
                        fontsize=10)
        ax.set_ylabel('angle [deg]')
    axes[-1].set_xlabel('time [s]')
    return _save(fig, path)


def plot_terms(case: CaseResult, path: str | pathlib.Path, title: str | None = None,
               joint: int | None = None, averaged: bool = False) -> pathlib.Path:
    """Figs. 7/8: the terms of eq. (11) at the joint against time, M_total − g_i against h_i,
    and the closure (always the exact one of the recorded accelerations).

    :param averaged: the inertia terms with the accelerations averaged over each sampling
        interval (``CaseResult.averaged``) instead of the instantaneous ones.
    """
    exact: JointDecomposition = case.decompositions[case.joint if joint is None else joint]
    d = case.averaged(exact) if averaged else exact
    i = _index(d.name)
    t = d.t
    fig, axes = _figure(3, height=2.7)
    ax = axes[0]
    ax.plot(t, d.m_total, color='tab:purple', lw=1.4, label=f'M_total = −Σ M_{i},j q̈_j')
    ax.plot(t, -d.m_total, color='tab:purple', lw=0.8, ls='--', alpha=0.7,
            label=f'Σ M_{i},j q̈_j')
    ax.plot(t, d.gravity, color='tab:green', lw=1.4, label=f'g_{i}')
    ax.plot(t, d.coriolis, color='tab:orange', lw=1.4, label=f'h_{i}')
    ax.plot(t, d.damping, color='tab:brown', lw=1.0, label=f'd_{i} q̇_{i}')
    ax.plot(t, d.tau, color='k', lw=1.0, label=f'τ_{i}')
    ax.plot(t, d.own_inertia, color='tab:cyan', lw=1.0, label=f'M_{i},{i} q̈_{i}')
    if np.any(np.nan_to_num(d.limit) != 0.0):
        ax.plot(t, d.limit, color='tab:pink', lw=1.0, label='soft stop')
    if np.any(np.nan_to_num(d.constraint) != 0.0):
        ax.plot(t, d.constraint, color='tab:olive', lw=1.0, label='swing constraint')
    ax.set_ylabel('torque [N m]')
    clip_to_bulk(ax, [d.m_total, d.gravity, d.coriolis, d.damping, d.tau, d.own_inertia],
                 note='; full values in the CSV')
    _mark_steps(ax, case)
    legend_above(ax, ncol=6, title=title or f'{case.label}: terms of eq. (11) at {d.name}'
                 + (' (q̈ averaged over each sampling interval)' if averaged else ''))

    ax = axes[1]
    ax.plot(t, d.m_total - d.gravity, color='tab:purple', lw=1.3, label=f'M_total − g_{i}')
    ax.plot(t, -d.m_total - d.gravity, color='tab:purple', lw=0.8, ls='--', alpha=0.7,
            label=f'Σ M_{i},j q̈_j − g_{i}')
    ax.plot(t, d.coriolis, color='tab:orange', lw=1.3, label=f'h_{i}')
    clip_to_bulk(ax, [d.m_total - d.gravity, -d.m_total - d.gravity, d.coriolis],
                 note='; full values in the CSV')
    ax.set_ylabel('torque [N m]')
    _mark_steps(ax, case, legend=False)
    legend_above(ax, ncol=6)

    ax = axes[2]
    rel = np.where(exact.valid, np.maximum(exact.residual_rel, 1e-18), np.nan)
    ax.semilogy(t, rel, color='0.3', lw=1.0,
                label='|closure residual| / Σ|terms| (recorded q̈)')
    ax.axhline(1e-9, color='tab:red', lw=0.8, ls='--', label='1e-9')
    ax.set_ylabel('relative residual')
    ax.set_xlabel('time [s]')
    _mark_steps(ax, case, legend=False)
    legend_above(ax)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    return _save(fig, path)


def plot_coupling(case: CaseResult, path: str | pathlib.Path, top: int = 6,
                  joint: int | None = None) -> pathlib.Path:
    """The ``top`` coupling terms M_ij q̈_j by RMS (over the analysis window) and M_total."""
    d = case.decompositions[case.joint if joint is None else joint]
    ranking = case.ranking(d.joint)[:top]
    series = {name: d.coupling[:, COORDINATE_NAMES.index(name)] for name, _ in ranking}
    fig, (ax,) = _figure(1, height=3.6)
    i = _index(d.name)
    for name, value in ranking:
        ax.plot(d.t, series[name], lw=1.0, label=f'M_{i},{_index(name)} q̈_{_index(name)} '
                f'(RMS {value:.3g})')
    ax.plot(d.t, d.m_total, color='k', lw=1.4, label='M_total')
    clip_to_bulk(ax, [d.m_total] + [series[name] for name, _ in ranking],
                 note='; full values in the CSV')
    _mark_steps(ax, case)
    ax.set_xlabel('time [s]')
    ax.set_ylabel('torque [N m]')
    ax.grid(True, alpha=0.3)
    legend_above(ax, ncol=4,
                 title=f'{case.label}: largest coupling terms at {d.name} (ranked by RMS)')
    return _save(fig, path)


def plot_mode_coverage(coverage: Coverage, path: str | pathlib.Path) -> pathlib.Path:
    """The gait-transition diagram of what ``coverage`` visited, laid out like the paper's
    Fig. 3: Table 2's modes as nodes, the support-foot states as rows and the swing-foot states
    as columns; an entered mode filled (its entries below its number), one never entered grey;
    each visited transition an arrow, as wide as its count's logarithm, labelled with it (a
    transition into the same mode, a resolved switch cycle that changed only the side or pivot,
    is counted beside the node)."""
    from matplotlib.patches import Circle, FancyArrowPatch

    from iceskate_sim.model.modes import SUPPORT_STATES, SWING_STATES, TABLE_2
    supports, swings = list(SUPPORT_STATES), list(SWING_STATES)
    where = {mode: (2.2 * swings.index(swing), -1.6 * supports.index(support))
             for mode, (support, swing) in TABLE_2.items()}
    fig, (ax,) = _figure(1, height=5.4, width=10.0)
    ax.set_aspect('equal')
    ax.axis('off')
    pairs: dict[tuple[int, int], int] = {}
    for (a, b, _), n in coverage.transitions.items():
        pairs[(a, b)] = pairs.get((a, b), 0) + n
    radius = 0.42
    for (a, b), n in sorted(pairs.items()):
        if a == b:
            x, y = where[a]
            ax.text(x + radius, y + radius, f'↻{n}', fontsize=7, color='tab:blue')
            continue
        arrow = FancyArrowPatch(where[a], where[b], connectionstyle='arc3,rad=0.18',
                                arrowstyle='-|>', mutation_scale=9, shrinkA=14, shrinkB=14,
                                lw=0.6 + 0.5 * np.log10(n), color='tab:blue', alpha=0.75)
        ax.add_patch(arrow)
        (xa, ya), (xb, yb) = where[a], where[b]
        # the label on the arc's side of the chord, near its middle
        mx, my = (xa + xb) / 2 + 0.18 * (yb - ya), (ya + yb) / 2 - 0.18 * (xb - xa)
        ax.text(mx, my, str(n), fontsize=6.5, color='tab:blue', ha='center', va='center')
    most = max(coverage.entries.values(), default=1)
    for mode, (x, y) in where.items():
        entries = coverage.entries[mode]
        shade = 0.25 + 0.75 * np.log1p(entries) / np.log1p(most) if entries else 0.0
        ax.add_patch(Circle((x, y), radius, facecolor=(0.12, 0.47, 0.71, shade) if entries
                            else '0.9', edgecolor='k' if entries else '0.6', lw=0.8))
        ax.text(x, y + 0.08, str(mode), ha='center', va='center', fontsize=11,
                fontweight='bold', color='k' if entries else '0.55')
        ax.text(x, y - 0.2, f'{entries}x' if entries else 'never', ha='center', va='center',
                fontsize=6.5, color='k' if entries else '0.55')
    for k, swing in enumerate(swings):
        ax.text(2.2 * k, 0.85, f'{swing}\n{SWING_STATES[swing][2]}', ha='center',
                va='bottom', fontsize=7.5)
    for k, support in enumerate(supports):
        ax.text(-0.8, -1.6 * k, f'{support}\n{SUPPORT_STATES[support][2]}', ha='right',
                va='center', fontsize=7.5, wrap=True)
    ax.set_xlim(-3.6, 2.2 * (len(swings) - 1) + 0.9)
    ax.set_ylim(-1.6 * (len(supports) - 1) - 0.8, 1.6)
    ax.set_title(f'Modes of Table 2 entered: {len(coverage.visited)} of {len(TABLE_2)} '
                 f'({len(coverage.runs)} run(s)); columns: swing foot, rows: support foot',
                 fontsize=9)
    return _save(fig, path)
