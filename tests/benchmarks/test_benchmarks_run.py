"""Every benchmark runs end to end on a tiny case and prints its figures.

The benchmarks are what the speed and accuracy claims of the documents come from; nothing else
runs them, so an interface they use can change under them unnoticed. These runs check that each
one still starts, runs and reports (not its timings: those are the benchmarks' own business).
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
BENCH = REPO / 'benchmarks'

CASES = {
    'bench_bag_write': (['stand', '--duration', '0.3', '--rounds', '1'],
                        'the two bags hold the same messages'),
    'bench_command': (['stand', '--rounds', '1', '--duration', '0.1'], 'whole command [s]'),
    'bench_view': (['stand', '--rounds', '1', '--duration', '0.1'], 'view / no view'),
    'bench_dynamics': (['--repeat', '1', '--number', '2'], '18-coordinate modes: worst evaluate'),
    'bench_figures': (['stand', '--duration', '0.2', '--repeat', '1', '--settings',
                       'implicit_euler:1e-3,ros34pw2:1e-2'], 'goals: every figure within'),
    'bench_period': (['stand', '--duration', '0.05', '--no-picture'],
                     "the run's own / the native loop's"),
    'bench_physics': (['--states', '2', '--spacing', '2', '--repeat', '1', '--number', '2',
                       '--warmup', '0.05'], 'ratios ours / mj_step implicitfast'),
    'bench_laws': (['stand', '--duration', '0.05'], 'native laws (Controller.compute)'),
    'bench_laziness': (['--quick', '--duration', '0.3', '--no-profile', '--out', '{tmp}'],
                       'identical results where expected: True'),
    'bench_work_precision': (['--quick', '--cases', 'passive', '--no-headline', '--out', '{tmp}'],
                             'reference converged'),
    'bench_sweep': (['--runs', '2', '--duration', '0.05', '--repeat', '1'],
                    'per-run overhead beyond the simulation'),
    'stress': (['--short', '--cases', 'kp_x10', '--long', '--long-duration', '0.5', '--window',
                '0.25'], 'long run: completed'),
}


@pytest.mark.slow
@pytest.mark.parametrize('name', sorted(CASES))
def test_the_benchmark_runs_and_reports(name: str, tmp_path: pathlib.Path) -> None:
    if name == 'bench_physics':
        pytest.importorskip('mujoco')
    arguments, expected = CASES[name]
    command = [sys.executable, str(BENCH / f'{name}.py'),
               *(a.format(tmp=tmp_path) for a in arguments)]
    env = {**os.environ, 'RAY_USAGE_STATS_ENABLED': '0'}
    done = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert expected in done.stdout, done.stdout[-2000:]
    assert 'Traceback' not in done.stderr, done.stderr[-2000:]
