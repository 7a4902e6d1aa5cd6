#!/usr/bin/env python3
"""Throughput of parameter sweeps: runs per minute on 1 and on 2 local workers, and the per-run
overhead beyond the simulation itself.

The sweep: ``--runs`` points of the ``skate`` scene (``--duration`` s each, no bag),
one axis over the friction so that every run is a different scene. Each round runs it with one
worker, then with two, into fresh folders (``iceskate_study.sweep.run_sweep``, the whole
sweep: validation, pool start-up, the runs, the table); ``--repeat`` rounds, and the medians
are compared:

* **ratio**: runs per minute with 2 workers over runs per minute with 1 (goal >= 1.9 on this
  2-core machine);
* **overhead**: per run, what the sweep's time holds beyond the simulation loop (each run's
  ``wall_time_s`` in metrics.json), over that loop's time (goal <= 2 % for 15 s runs). With
  1 worker, from a sweep of ``--runs`` and one of three times as many: the time beyond the runs'
  loops grows by twice ``--runs`` runs' overhead from one to the other (the pool's start-up,
  once a sweep, cancels; it varies by about 0.1 s from sweep to sweep). That comes apart into
  the part inside the worker (scene validation, session set-up, metrics: each run's
  ``worker_time_s`` less its loop) and the rest (each run's hand-over and table row); the
  pool's start-up is shown in seconds a sweep;
* **10,000 runs**: the time 10,000 such runs take at the 2-worker rate (goal <= 10 min for
  15 s runs of ``skate``).

Usage (from the repository root, environment sourced; under the machine's CPU lock):
    python benchmarks/bench_sweep.py [--runs 16] [--duration 15] [--repeat 2]
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import tempfile
import time

import pyarrow.parquet as pq

from iceskate_study.spec import parse_spec
from iceskate_study.sweep import run_sweep

GOAL_RATIO = 1.9  # runs per minute, 2 workers over 1
GOAL_OVERHEAD = 0.02  # per-run overhead over the simulation loop (15 s runs)
GOAL_10K_MIN = 10.0  # minutes for 10,000 runs of the 15 s skate scene
LONGER = 3  # the longer 1-worker sweep's runs, in --runs


def sweep_once(spec_raw: dict, workers: int, runs: int) -> tuple[float, list[dict]]:
    """One whole sweep into a fresh folder: its time [s] and its rows."""
    with tempfile.TemporaryDirectory(prefix='bench-sweep-') as tmp:
        out = pathlib.Path(tmp)
        spec = parse_spec(spec_raw, out / 'spec.yaml')
        start = time.perf_counter()
        result = run_sweep(spec, out / 'out', workers=workers, progress=False, maps=False)
        elapsed = time.perf_counter() - start
        rows = pq.read_table(result.table).to_pylist()
    assert len(rows) == runs and all(r['status'] == 'ok' for r in rows), rows
    return elapsed, rows


def main() -> int:
    """Run the rounds and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=16, help='runs per sweep')
    parser.add_argument('--duration', type=float, default=15.0, help='simulated s per run')
    parser.add_argument('--repeat', type=int, default=2, help='rounds (1 then 2 workers)')
    args = parser.parse_args()
    spec_raw = {'study': 'bench', 'scene': 'skate',
                'overrides': {'duration': args.duration},
                'axes': {'floor.mu': {'linspace': [0.004, 0.006, args.runs]}},
                'metrics': ['steps', 'wall_time_s']}
    rates: dict[int, list[float]] = {1: [], 2: []}
    overhead, inside, start_up = [], [], []
    for _ in range(args.repeat):
        for workers in (1, 2):
            elapsed, rows = sweep_once(spec_raw, workers, args.runs)
            rates[workers].append(60.0 * args.runs / elapsed)
            loop = statistics.fmean(r['wall_time_s'] for r in rows)
            if workers == 1:
                longer_spec = {**spec_raw, 'axes': {'floor.mu': {
                    'linspace': [0.004, 0.006, LONGER * args.runs]}}}
                longer, longer_rows = sweep_once(longer_spec, 1, LONGER * args.runs)
                beyond = elapsed - sum(r['wall_time_s'] for r in rows)
                per_run = (longer - sum(r['wall_time_s'] for r in longer_rows)
                           - beyond) / ((LONGER - 1) * args.runs)
                overhead.append(per_run / loop)
                inside.append(statistics.fmean(r['worker_time_s'] - r['wall_time_s']
                                               for r in rows + longer_rows) / loop)
                start_up.append(beyond - args.runs * per_run)
            print(f'{workers} worker{"s" if workers > 1 else " "}: {args.runs} runs in '
                  f'{elapsed:6.2f} s = {rates[workers][-1]:6.1f} runs/min (simulation loop '
                  f'{loop:.3f} s per run)', flush=True)
    one, two = statistics.median(rates[1]), statistics.median(rates[2])
    print(f'runs/min: 1 worker {one:.1f}, 2 workers {two:.1f}; ratio {two / one:.2f} '
          f'(goal >= {GOAL_RATIO:g})')
    print(f'per-run overhead beyond the simulation ({args.duration:g} s runs, 1 worker, '
          f'sweeps of {args.runs} and {LONGER * args.runs} runs): '
          f'{100 * statistics.median(overhead):.1f} % of the loop (goal <= '
          f'{100 * GOAL_OVERHEAD:g} %), {100 * statistics.median(inside):.1f} % of it in the '
          f"worker; and once a sweep (the pool's start-up, the last table write): "
          f'{statistics.median(start_up):.2f} s')
    print(f'10,000 runs of {args.duration:g} s at the 2-worker rate: {10_000 / two:.1f} min '
          f'(goal <= {GOAL_10K_MIN:g} min for 15 s runs)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
