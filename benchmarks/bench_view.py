#!/usr/bin/env python3
"""What the live view costs a run: ``run_scene SCENE --view --pace 0`` against the same run
without the view, as the user sees it (metrics.json's ``real_time_factor``).

Runs ``--duration`` s of a scene headless (``--ros``: through the node graph, the page fed by
its own node), alternately without and with the live page (unpaced, no browser attached: the
page is drawn for the server as it would be for a client; a browser adds its rendering on its
own process), ``--rounds`` times, and prints the median real-time factors and their ratio,
measured in this one run. The goal: the view costs <= 10 % (ratio >= 0.90).

Usage (from the repository root, environment sourced):
    python benchmarks/bench_view.py [skate] [--duration 15] [--rounds 3] [--ros]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import pathlib
import statistics
import tempfile

from bench_work_precision import machine_info

from iceskate_bringup.graph import run_graph
from iceskate_bringup.runner import simulate
from iceskate_bringup.scene import load_scene
from iceskate_bringup.watch import Watch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--duration', type=float, default=15.0, help='simulated seconds')
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--ros', action='store_true', help='through the ROS node graph')
    args = parser.parse_args()
    scene = replace(load_scene(args.scene), duration=args.duration)
    factors: dict[str, list[float]] = {'no view': [], 'view': []}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            for name, watch in (('no view', None), ('view', Watch(pace=0.0, port=0))):
                out = pathlib.Path(tmp) / f'{name.replace(" ", "_")}_{k}'
                if args.ros:
                    metrics = run_graph(args.scene, out, duration=args.duration, watch=watch)
                else:
                    outcome = simulate(scene, out, progress=False, watch=watch)
                    metrics, error = outcome.metrics, outcome.error
                    assert error is None, error
                factors[name].append(metrics['real_time_factor'])
    print(machine_info())
    print(f'{args.scene}{" through ROS" if args.ros else ""}, {args.duration:g} s simulated, '
          f'{args.rounds} rounds (medians):')
    for name, values in factors.items():
        print(f'  {name:8s} real-time factor {statistics.median(values):6.1f}  '
              f'({", ".join(f"{v:.1f}" for v in values)})')
    ratio = statistics.median(factors['view']) / statistics.median(factors['no view'])
    print(f'  view / no view: {ratio:.3f} (goal >= 0.90)')


if __name__ == '__main__':
    main()
