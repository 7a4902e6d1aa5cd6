"""The whole offline analysis of one bag, or of a pair (``--compare``: the paper's Figs. 5-8),
into a directory: per case (labelled by scene) the figures, a CSV of every series, optionally
the animation, and ``summary.json`` (docs/usage.md).
"""

from __future__ import annotations

from collections.abc import Callable
import json
import math
import pathlib
from typing import TYPE_CHECKING, Any

from iceskate_analysis.bag_io import BagReading
from iceskate_analysis.coupling import (
    RIGHT_SHOULDER,
    CaseResult,
    analyse_bag,
    parse_joint,
    robot_for_bag,
)
from iceskate_analysis.outputs import StagedFiles
from iceskate_sim.errors import InputRefused
from iceskate_sim.shutdown import raise_if_stopped

if TYPE_CHECKING:
    from iceskate_sim.shutdown import StopRequest

__all__ = ['case_label', 'jsonable', 'run_analysis']


def case_label(path: pathlib.Path, scene: str, taken: set[str]) -> str:
    """A file-name-safe label: the scene name, else the bag directory's name; made unique."""
    base = scene or (path.parent.name if path.name == 'bag' else path.stem) or 'run'
    base = ''.join(c if c.isalnum() or c in '-_' else '_' for c in base)
    label, n = base, 2
    while label in taken:
        label, n = f'{base}_{n}', n + 1
    taken.add(label)
    return label


def jsonable(value: Any) -> Any:
    """Nested data with non-finite floats replaced by None (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value


def _order_pair(cases: list[CaseResult]) -> tuple[CaseResult, CaseResult, str]:
    """(without τ8, with τ8, how it was decided)."""
    first, second = sorted(cases, key=lambda case: case.torso_yaw_input)  # stable
    if first.torso_yaw_input != second.torso_yaw_input:
        return first, second, 'yaw source'
    return first, second, 'argument order (both or neither have a torso-yaw source)'


def _ratio(a: float, b: float) -> float | None:
    return a / b if b and math.isfinite(a) and math.isfinite(b) else None


def run_analysis(bag: str | pathlib.Path, out: str | pathlib.Path,
                 joint: int | str = RIGHT_SHOULDER, compare: str | pathlib.Path | None = None,
                 animate: bool = False, frames: int = 120, progress: bool = False,
                 stop: StopRequest | None = None) -> dict[str, Any]:
    """Analyse ``bag`` (and ``compare``) and write figures, CSV and summary.json into ``out``.

    Every file is written under a hidden name and renamed to its own once all are complete
    (``StagedFiles``): on a signal or a failure ``out`` keeps what it held before.

    :param joint: the joint of eq. (11) (default 11, the right shoulder).
    :param animate: also write the stick-figure GIF and the key-frame strip of each case.
    :param frames: most frames of a GIF.
    :param stop: looked for at every record read, between blocks and between figures.
    :return: the summary (as written to summary.json).
    :raises InputRefused: on an unreadable bag or a bad joint (the message names it).
    :raises RunInterrupted: on a stop signal (t: how far into the run the analysis was).
    """
    from iceskate_analysis import plots
    joint = parse_joint(joint)
    out = pathlib.Path(out)
    if out.exists() and not out.is_dir():
        raise InputRefused(f'--out {out} exists and is not a directory')
    out.mkdir(parents=True, exist_ok=True)
    with StagedFiles(out) as staged:
        taken: set[str] = set()
        cases = []
        for path in [bag] + ([compare] if compare is not None else []):
            reading = BagReading(path, progress=progress, stop=stop)
            label = case_label(reading.path, reading.custom_data.get('scene', ''), taken)
            csv = f'{label}_series.csv'
            cases.append(analyse_bag(reading, label, joint, staged(csv), progress=progress,
                                     stop=stop))
        end = max(case.end_s for case in cases)

        def check(doing: str) -> None:
            raise_if_stopped(stop, end, doing)

        def draw(name: str, plot: Callable[..., object], *args: Any, **kwargs: Any) -> str:
            """``plot(*args, <staged file>, **kwargs)`` unless a stop signal came; ``name``."""
            check(f'drawing {name}')
            plot(*args, staged(name), **kwargs)
            return name
        name = cases[0].main.name
        files: dict[str, list[str]] = {}
        for case in cases:
            label = case.label
            files[label] = [
                draw(f'{label}_shoulders.png', plots.plot_shoulders, case),
                draw(f'{label}_terms_{name}.png', plots.plot_terms, case, averaged=True),
                draw(f'{label}_terms_{name}_instantaneous.png', plots.plot_terms, case),
                draw(f'{label}_coupling_{name}.png', plots.plot_coupling, case),
                f'{label}_series.csv',
            ]
            if animate:
                from iceskate_analysis.animation import render_gif, render_keyframes
                robot = robot_for_bag(case.kept)
                gif = f'{label}_animation.gif'
                files[label] += [
                    draw(gif, render_gif, case.kept, robot, max_frames=frames,
                         progress=progress, check=lambda gif=gif: check(f'drawing {gif}')),
                    draw(f'{label}_keyframes.png', render_keyframes, case.kept, robot)]
        summaries = {c.label: c.summary() for c in cases}
        summary: dict[str, Any] = {'joint': name, 'cases': summaries}
        if len(cases) == 2:
            without, with_yaw, decided = _order_pair(cases)

            def reading_of(case: CaseResult, joint: str) -> dict[str, float]:
                return summaries[case.label]['joints'][joint]['paper_reading']
            pairs = ((without, 'without', 5), (with_yaw, 'with', 6))
            paper = [draw(f'fig{n}_shoulders.png', plots.plot_shoulders, case,
                          title=f'Fig. {n}: shoulder angles {which} torso-yaw input τ8 '
                                f'({case.label})') for case, which, n in pairs]
            paper += [draw(f'fig{n + 2}_terms_{name}.png', plots.plot_terms, case,
                           title=f'Fig. {n + 2}: terms of eq. (11) at {name} {which} τ8, q̈ '
                                 f'averaged over each interval ({case.label})', averaged=True)
                      for case, which, n in pairs]
            paper += [draw(f'fig{n + 2}_terms_{name}_instantaneous.png', plots.plot_terms,
                           case, title=f'Fig. {n + 2}, the recorded (instantaneous) q̈ '
                                       f'({case.label})') for case, _, n in pairs]
            paper.append(draw('compare_shoulders.png', plots.plot_compare_shoulders,
                              [without, with_yaw]))
            files['comparison'] = paper
            a, b = without.arms, with_yaw.arms
            summary['comparison'] = {
                'without_yaw': without.label, 'with_yaw': with_yaw.label,
                'assigned_by': decided,
                'arm_peak_to_peak_ratio_with_over_without': {
                    arm: _ratio(b.peak_to_peak[arm], a.peak_to_peak[arm])
                    for arm in ('q11', 'q14')},
                'rms_coriolis_ratio_with_over_without': _ratio(
                    summaries[with_yaw.label]['rms']['coriolis'],
                    summaries[without.label]['rms']['coriolis']),
                # the paper's reading of Figs. 7/8 at both shoulders: M_total ~ g_i in both
                # runs, h_i changed by τ8
                'paper_reading': {
                    joint: {
                        'without_yaw': reading_of(without, joint),
                        'with_yaw': reading_of(with_yaw, joint),
                        'rms_h_with_over_without': _ratio(reading_of(with_yaw, joint)['rms_h'],
                                                          reading_of(without, joint)['rms_h'])}
                    for joint in summaries[without.label]['joints']},
            }
        summary['files'] = files
        summary = jsonable(summary)
        staged('summary.json').write_text(json.dumps(summary, indent=2) + '\n',
                                          encoding='utf-8')
        check('writing summary.json')
        staged.commit()  # summary.json last
    return summary
