#!/usr/bin/env python3
"""The figures a run reports against a converged run's, and what they cost: for each integrator
setting, the run's own real-time factor (``metrics.json``'s, the same headless run as
``run_scene`` without outputs) and the largest deviation of any figure of its ``metrics.json``
from the reference's: a count (steps, transitions, samples) must be equal, a fraction (mode
time, ZMP outside the support) within 0.001, every other figure (distance, head error RMS, arm
swing, support positions, ...) within 0.1 % of the reference's. The figures of the integrator
itself (wall time, steps, evaluations, constraint drift) are not compared.

The reference is rk45 at the tightest tolerance its step-size control holds over the scene
(``--reference-rtol``; 1e-9 for the whole ``skate``), checked against the same run 10x looser:
its largest deviation is printed first and must be far below the 0.1 % it judges.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_figures.py [skate] [--settings implicit_euler:1e-3,ros34pw2:1e-2]
        [--duration S] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from typing import Any

from iceskate_bringup.api import run
from iceskate_bringup.scene import load_scene
from iceskate_sim.physics.integrators import FIXED_STEP

GOAL_RTF = 30.0  # the run's own real-time factor at the shipped setting
GOAL_RELATIVE = 1e-3  # every figure within 0.1 % of the reference's ...
GOAL_FRACTION = 1e-3  # ... a fraction within 0.001, a count equal
#: the integrator's own figures: not the run's results
NOT_COMPARED = ('wall_time_s', 'real_time_factor', 'physics_steps', 'dynamics_evaluations',
                'max_constraint_drift', 'max_constraint_residual')
COUNTS = ('steps', 'transitions', 'suppressed_cycles', 'resolved_cycles', 'samples')
DEFAULT_SETTINGS = ('implicit_euler:1e-3,ros34pw2:1e-1,ros34pw2:3e-2,ros34pw2:1e-2,'
                    'ros34pw2:1e-3,rk45:1e-4')


def figures(metrics: dict[str, Any], prefix: str = '') -> dict[str, float]:
    """The numeric figures of a metrics.json, by dotted key (list entries as key[i])."""
    out: dict[str, float] = {}
    for key, value in metrics.items():
        name = prefix + key
        if isinstance(value, dict):
            out.update(figures(value, name + '.'))
        elif isinstance(value, list):
            out.update({f'{name}[{i}]': float(x) for i, x in enumerate(value)
                        if isinstance(x, (int, float)) and not isinstance(x, bool)})
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            out[name] = float(value)
    return {k: v for k, v in out.items() if not k.startswith(NOT_COMPARED)}


def score(key: str, value: float, reference: float) -> float:
    """One figure's deviation over what the goal allows (<= 1: within it): a count must be
    equal, a fraction within 0.001, any other figure within 0.1 % of the reference's."""
    if key.rsplit('.', 1)[-1] in COUNTS:
        return 0.0 if value == reference else float('inf')
    if 'fraction' in key:
        return abs(value - reference) / GOAL_FRACTION
    return abs(value - reference) / max(abs(reference), 1e-12) / GOAL_RELATIVE


def compare(got: dict[str, float], reference: dict[str, float]) -> dict[str, Any]:
    """The three worst figures of ``got`` against ``reference`` as (score, key, reference,
    value), and whether all are within the goal."""
    rows = sorted(((score(key, got.get(key, float('nan')), ref), key, ref,
                    got.get(key, float('nan'))) for key, ref in reference.items()),
                  key=lambda row: -row[0] if row[0] == row[0] else -float('inf'))
    return {'all_within': all(row[0] <= 1.0 for row in rows), 'worst': rows[:3]}


def setting_overrides(method: str, setting: float) -> dict[str, Any]:
    """A scene's integrator keys for ``method`` at ``setting`` (a fixed step [s], or an
    adaptive method's rtol with atol 1e-2 rtol and a largest step of 1 ms, the shipped scenes'
    control period)."""
    if method in FIXED_STEP:
        return {'integrator.method': method, 'integrator.step': setting}
    return {'integrator.method': method, 'integrator.rtol': setting,
            'integrator.atol': setting * 1e-2, 'integrator.step': 1e-3}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--settings', default=DEFAULT_SETTINGS,
                        help='comma-separated method:setting (a step [s] or an rtol)')
    parser.add_argument('--duration', type=float, help='simulated seconds (default the scene)')
    parser.add_argument('--repeat', type=int, default=3, help='runs per setting (median RTF)')
    parser.add_argument('--reference-rtol', type=float, default=1e-9)
    args = parser.parse_args(argv)
    base = {} if args.duration is None else {'duration': args.duration}
    scene = load_scene(args.scene, base)
    print(f'scene {args.scene}: {scene.duration:g} s; reference rk45 rtol '
          f'{args.reference_rtol:g}', flush=True)
    reference = run(scene, setting_overrides('rk45', args.reference_rtol))
    check = run(scene, setting_overrides('rk45', args.reference_rtol * 10.0))
    ref_figures = figures(reference.metrics)
    converged = compare(figures(check.metrics), ref_figures)
    worst = converged['worst'][0]
    print(f'reference converged: rtol {args.reference_rtol * 10:g} against it, worst figure '
          f'{worst[1]} {worst[3]:.6g} against {worst[2]:.6g} (all within the goal: '
          f'{converged["all_within"]})')
    print(f'{"setting":>22s} {"RTF (median)":>13s}  all figures within 0.1 %  worst figures')
    for item in args.settings.split(','):
        method, value = item.split(':')
        overrides = setting_overrides(method, float(value))
        rtfs, result = [], None
        for _ in range(max(1, args.repeat)):
            result = run(scene, overrides)
            rtfs.append(result.metrics['real_time_factor'])
        outcome = compare(figures(result.metrics), ref_figures)
        worst = '; '.join(f'{k} {g:.6g} ({r:.6g})' for _, k, r, g in outcome['worst'])
        print(f'{method + " " + value:>22s} {statistics.median(rtfs):12.1f}x  '
              f'{str(outcome["all_within"]):>5s}  {worst}', flush=True)
    print(f'goals: every figure within 0.1 % (fractions 0.001, counts equal) at >= '
          f'{GOAL_RTF:g}x real time as the run reports it')
    return 0


if __name__ == '__main__':
    sys.exit(main())
