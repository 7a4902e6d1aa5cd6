#!/usr/bin/env python3
"""What a user waits for: ``run_scene SCENE --out DIR`` as a whole command, start to exit.

Starts the command ``--rounds`` times as a new process (imports, the run, the bag, metrics,
trajectory and summary.png: everything before the prompt returns) into a fresh folder each
time, and prints the wall time of each, their median and spread, and the run's own real-time
factor (metrics.json), beside the machine's load when it started: all measured in this one
run. ``--ros`` times ``run_scene SCENE --ros`` (the node graph) instead.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_command.py [skate] [--rounds 5] [--ros] [more run_scene options]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import statistics
import subprocess
import tempfile
import time

from bench_work_precision import machine_info

GOAL_S = 1.0  # the whole run_scene skate --out DIR command, start to exit [s]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--rounds', type=int, default=5, choices=range(1, 101),
                        metavar='1..100')
    parser.add_argument('--ros', action='store_true', help='run_scene --ros (the node graph)')
    args, extra = parser.parse_known_args()  # the rest: run_scene's own options
    print(machine_info())
    walls, factors = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            out = pathlib.Path(tmp) / f'run_{k}'
            command = ['run_scene', args.scene, '--out', str(out), '--quiet',
                       *(['--ros'] if args.ros else []), *extra]
            started = time.perf_counter()
            done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  text=True)
            walls.append(time.perf_counter() - started)
            if done.returncode != 0:
                raise SystemExit(f'bench_command: {" ".join(command)} failed:\n{done.stderr}')
            factors.append(json.loads((out / 'metrics.json').read_text())['real_time_factor'])
    print(f'{" ".join(command[:2])}{" --ros" if args.ros else ""} {" ".join(extra)}, '
          f'{args.rounds} rounds:')
    print(f'  whole command [s]: median {statistics.median(walls):.2f}, '
          f'{min(walls):.2f}-{max(walls):.2f} ({", ".join(f"{w:.2f}" for w in walls)})'
          + ('' if args.ros or args.scene != 'skate' or extra else f'; goal <= {GOAL_S:g} s: '
             + ('met' if statistics.median(walls) <= GOAL_S else 'NOT met')))
    print(f"  the run's real-time factor (metrics.json): median "
          f'{statistics.median(factors):.1f} ({", ".join(f"{f:.1f}" for f in factors)})')


if __name__ == '__main__':
    main()
