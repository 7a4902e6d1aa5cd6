#!/usr/bin/env python3
"""Speed of the ROS 2 lockstep graph at a 1 ms control period (a benchmark, not a test).

For each scene it runs ``--duration`` simulated seconds (bag recorded, as ``run_scene``) three
ways and prints the real-time factor (simulated / wall time of the control loop):

* headless: ``iceskate_sim.runner.run`` (physics + laws, no transport), the lower bound;
* graph, 3 processes: simulator, visual_lifting, gait_manager as separate processes;
* graph, 1 process: the three nodes on one EventsExecutor.

From the simulator's loop timings (``stats_file``) it prints, per control period, the median,
p95 and p99 of the round trip (state published -> last command in) and the median and p99 of
the physics step. The per-hop latency is estimated as (round trip - slowest controller's
compute) / 2, with the controllers' compute timed in this process on the scene's initial
observation.

Usage (from the repository root, after ``make setup`` and ``. ./env.sh``):
    python benchmarks/bench_graph.py [--duration 0.5] [--scenes skate tests/...yaml] [--json F]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
import pathlib
import statistics
import sys
import tempfile
import timeit

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
DEFAULT_SCENES = ['skate', str(REPO_ROOT / 'tests' / 'integration' / 'data' / 'tiny_stand.yaml')]


def controller_compute_ms(scene) -> dict[str, float]:
    """Median time [ms] of each controller node's law evaluation at the initial state."""
    from gait_manager.law import GaitManagerParameters, gait_manager_commands, head_offset
    from iceskate_sim.dynamics import GaitDynamics
    from iceskate_sim.robot import load_robot
    from iceskate_sim.simulation import Simulator
    from visual_lifting.law import VisualLiftingParameters, visual_lifting
    robot = load_robot()
    obs = Simulator(robot, scene.simulator, scene.initial).observation()
    dynamics = GaitDynamics(robot)
    gm = (GaitManagerParameters.from_dict(scene.gait_manager or {})
          if scene.gait_manager is not None else None)
    out = {}
    if scene.visual_lifting is not None:
        vl = VisualLiftingParameters.from_dict(scene.visual_lifting or {})
        psi0 = dynamics.head_pose(obs.contact(), obs.q)[0]

        def vl_call():
            visual_lifting(obs, dynamics, vl, psi0, head_offset(obs, dynamics, gm) if gm else
                           (0.0, 0.0))
        out['visual_lifting'] = _median_ms(vl_call)
    if gm is not None:
        out['gait_manager'] = _median_ms(lambda: gait_manager_commands(obs, dynamics, gm))
    return out


def _median_ms(func) -> float:
    func()
    return statistics.median(timeit.Timer(func).repeat(repeat=7, number=50)) / 50 * 1e3


def bench_scene(scene_arg: str, duration: float, work: pathlib.Path) -> dict:
    """Headless, 3-process and 1-process runs of one scene."""
    from iceskate_sim.graph import run_graph
    from iceskate_sim.runner import run
    from iceskate_sim.scene import load_scene
    scene = replace(load_scene(scene_arg), duration=duration)
    name = scene.name
    result = {'scene': name, 'duration_s': duration,
              'control_period_s': scene.simulator.control_period,
              'controller_compute_ms': controller_compute_ms(scene)}
    result['headless_rtf'] = run(scene, work / f'{name}-headless', progress=False)[
        'real_time_factor']
    for label, single in (('three_process', False), ('single_process', True)):
        out = work / f'{name}-{label}'
        stats = work / f'{name}-{label}-stats.json'
        metrics = run_graph(scene_arg, out, duration=duration, single_process=single,
                            stats_file=str(stats), timeout=600.0)
        loop = json.loads(stats.read_text())
        result[label] = {'rtf': metrics['real_time_factor'],
                         'round_trip_ms': [1e3 * x for x in loop['round_trip']],
                         'physics_ms': [1e3 * x for x in loop['physics']],
                         'periods': loop['periods']}
    slowest = max(result['controller_compute_ms'].values(), default=0.0)
    for label in ('three_process', 'single_process'):
        rt = result[label]['round_trip_ms'][0]
        result[label]['hop_estimate_ms'] = max(0.0, (rt - slowest) / 2.0)
    return result


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=DEFAULT_SCENES)
    parser.add_argument('--duration', type=float, default=0.5, help='simulated s per run')
    parser.add_argument('--json', type=pathlib.Path, help='also write the figures here')
    args = parser.parse_args(argv)
    results = []
    with tempfile.TemporaryDirectory(prefix='bench-graph-') as tmp:
        for scene in args.scenes:
            r = bench_scene(scene, args.duration, pathlib.Path(tmp))
            results.append(r)
            print(f"\nscene {r['scene']}: {r['duration_s']} s at "
                  f"{1e3 * r['control_period_s']:g} ms; controller compute "
                  + ', '.join(f'{k} {v:.2f} ms' for k, v in r['controller_compute_ms'].items()))
            print(f"  headless               RTF {r['headless_rtf']:.3f}")
            for label in ('three_process', 'single_process'):
                g = r[label]
                rt, ph = g['round_trip_ms'], g['physics_ms']
                print(f'  graph {label:<16} RTF {g["rtf"]:.3f}; round trip median/p95/p99 '
                      f'{rt[0]:.2f}/{rt[1]:.2f}/{rt[2]:.2f} ms; physics median/p99 '
                      f'{ph[0]:.2f}/{ph[2]:.2f} ms; hop ~ {g["hop_estimate_ms"]:.2f} ms')
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
