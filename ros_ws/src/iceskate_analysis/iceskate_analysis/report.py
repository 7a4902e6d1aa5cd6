"""The whole offline analysis of one bag, or of a pair (``--compare``: the paper's Figs. 5-8),
into a directory: per case (labelled by scene) the figures, a CSV of every series, optionally
the animation, and ``summary.json`` (docs/usage.md).
"""

from __future__ import annotations

import json
import math
import pathlib
from typing import Any

from iceskate_analysis.bag_io import BagReading
from iceskate_analysis.coupling import (
    RIGHT_SHOULDER,
    CaseResult,
    analyse_bag,
    parse_joint,
    robot_for_bag,
)
from iceskate_sim.errors import SimulationError

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
                 ) -> dict[str, Any]:
    """Analyse ``bag`` (and ``compare``) and write figures, CSV and summary.json into ``out``.

    :param joint: the joint of eq. (11) (default 11, the right shoulder).
    :param animate: also write the stick-figure GIF and the key-frame strip of each case.
    :param frames: most frames of a GIF.
    :return: the summary (as written to summary.json).
    :raises SimulationError: on an unreadable bag or a bad joint (the message names it).
    """
    from iceskate_analysis import plots
    joint = parse_joint(joint)
    out = pathlib.Path(out)
    if out.exists() and not out.is_dir():
        raise SimulationError(f'--out {out} exists and is not a directory')
    out.mkdir(parents=True, exist_ok=True)
    taken: set[str] = set()
    cases = []
    for path in [bag] + ([compare] if compare is not None else []):
        reading = BagReading(path, progress=progress)
        label = case_label(reading.path, reading.custom_data.get('scene', ''), taken)
        cases.append(analyse_bag(reading, label, joint, out / f'{label}_series.csv',
                                 progress=progress))
    name = cases[0].main.name
    files: dict[str, list[str]] = {}
    for case in cases:
        written = [
            plots.plot_shoulders(case, out / f'{case.label}_shoulders.png'),
            plots.plot_terms(case, out / f'{case.label}_terms_{name}.png', averaged=True),
            plots.plot_terms(case, out / f'{case.label}_terms_{name}_instantaneous.png'),
            plots.plot_coupling(case, out / f'{case.label}_coupling_{name}.png'),
            out / f'{case.label}_series.csv',
        ]
        if animate:
            from iceskate_analysis.animation import render_gif, render_keyframes
            robot = robot_for_bag(case.kept)
            written.append(render_gif(case.kept, robot, out / f'{case.label}_animation.gif',
                                      max_frames=frames, progress=progress))
            written.append(render_keyframes(case.kept, robot,
                                            out / f'{case.label}_keyframes.png'))
        files[case.label] = [p.name for p in written]
    summaries = {c.label: c.summary() for c in cases}
    summary: dict[str, Any] = {'joint': name, 'cases': summaries}
    if len(cases) == 2:
        without, with_yaw, decided = _order_pair(cases)

        def reading(case: CaseResult, joint: str) -> dict[str, float]:
            return summaries[case.label]['joints'][joint]['paper_reading']
        pairs = ((without, 'without', 5), (with_yaw, 'with', 6))
        paper = [plots.plot_shoulders(case, out / f'fig{n}_shoulders.png',
                                      f'Fig. {n}: shoulder angles {which} torso-yaw input τ8 '
                                      f'({case.label})') for case, which, n in pairs]
        paper += [plots.plot_terms(case, out / f'fig{n + 2}_terms_{name}.png',
                                   f'Fig. {n + 2}: terms of eq. (11) at {name} {which} τ8, q̈ '
                                   f'averaged over each interval ({case.label})', averaged=True)
                  for case, which, n in pairs]
        paper += [plots.plot_terms(case, out / f'fig{n + 2}_terms_{name}_instantaneous.png',
                                   f'Fig. {n + 2}, the recorded (instantaneous) q̈ '
                                   f'({case.label})') for case, _, n in pairs]
        paper.append(plots.plot_compare_shoulders([without, with_yaw],
                                                  out / 'compare_shoulders.png'))
        files['comparison'] = [p.name for p in paper]
        a, b = without.arms, with_yaw.arms
        summary['comparison'] = {
            'without_yaw': without.label, 'with_yaw': with_yaw.label, 'assigned_by': decided,
            'arm_peak_to_peak_ratio_with_over_without': {
                arm: _ratio(b.peak_to_peak[arm], a.peak_to_peak[arm]) for arm in ('q11', 'q14')},
            'rms_coriolis_ratio_with_over_without': _ratio(
                summaries[with_yaw.label]['rms']['coriolis'],
                summaries[without.label]['rms']['coriolis']),
            # the paper's reading of Figs. 7/8 at both shoulders: M_total ~ g_i in both runs,
            # h_i changed by τ8
            'paper_reading': {
                joint: {
                    'without_yaw': reading(without, joint), 'with_yaw': reading(with_yaw, joint),
                    'rms_h_with_over_without': _ratio(reading(with_yaw, joint)['rms_h'],
                                                      reading(without, joint)['rms_h'])}
                for joint in summaries[without.label]['joints']},
        }
    summary['files'] = files
    summary = jsonable(summary)
    (out / 'summary.json').write_text(json.dumps(summary, indent=2) + '\n', encoding='utf-8')
    return summary
