#!/usr/bin/env python3
"""What skipping saves: the same scene with the skipping on and off.

On the ``stand`` scene (visual lifting plus 2 of the 6 gait-manager sources, a chest push at
2 s), headless, shipped integrator (the laws compute only the enabled sources):

* **recording**: ``run_scene`` with the bag and ``trajectory.npz`` written against the bag off
  against no output at all (trajectories of the first two compared bit for bit);
* **projection**: the end-of-period projection onto the swing constraints on against off (this
  one changes the results: the drift it removes is reported, not an equality);
* **per source**: the cost of one evaluation of each control source at the scene's initial
  observation, the native law as the nodes and the runner call it (what a scene that disables
  it saves per control period).

Wall times are the median of ``--repeat`` runs, on and off interleaved. Then one run of the
scene is profiled with pyinstrument: the top functions by own time and by total time are
printed and the HTML profile is written to ``--out``/profile_stand.html. Figures also go to
``--out``/laziness.json and laziness.md.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_laziness.py [--out runs/bench] [--quick] [--repeat 3]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
import pathlib
import statistics
import sys
import tempfile
import time
import timeit
from typing import Any

from bench_work_precision import REPO_ROOT, machine_info, simulate
import numpy as np

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene, scene_sources
from iceskate_sim.model.robot import load_robot
from iceskate_sim.run.scene import Scene


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float('nan')


def _obs(scene: Scene, robot: Any):
    from iceskate_sim.physics.simulation import Simulator
    return Simulator(robot, scene.simulator, scene.initial).observation()


def compare_recording(scene: Scene, duration: float, repeat: int, log) -> dict:
    """run_scene with bag + files, files only, nothing."""
    from iceskate_bringup.runner import run
    walls: dict[str, list[float]] = {'bag': [], 'files': [], 'none': []}
    totals: dict[str, list[float]] = {k: [] for k in walls}
    trajectories = {}
    scene = replace(scene, duration=duration)
    with tempfile.TemporaryDirectory(prefix='iceskate_laziness_') as tmp:
        for k in range(repeat):
            for name in walls:
                out = None if name == 'none' else pathlib.Path(tmp) / f'{name}{k}'
                s = replace(scene, record_bag=(name == 'bag'))
                start = time.perf_counter()
                metrics = run(s, out, progress=False)
                totals[name].append(time.perf_counter() - start)
                walls[name].append(metrics['wall_time_s'])
                if out is not None:
                    with np.load(out / 'trajectory.npz') as data:
                        trajectories[name] = (data['q'].copy(), data['v'].copy())
    identical = (np.array_equal(trajectories['bag'][0], trajectories['files'][0])
                 and np.array_equal(trajectories['bag'][1], trajectories['files'][1]))
    out = {'duration_s': duration, 'repeat': repeat,
           'loop_wall_s': walls, 'total_wall_s': totals,
           'median_loop_s': {k: _median(v) for k, v in walls.items()},
           'median_total_s': {k: _median(v) for k, v in totals.items()},
           'identical_q_v_bag_vs_files': bool(identical)}
    m = out['median_total_s']
    log(f'[recording] total wall: bag {m["bag"]:.2f} s, files only {m["files"]:.2f} s, '
        f'nothing {m["none"]:.2f} s; identical q and v with and without the bag: {identical}')
    return out


def compare_projection(scene: Scene, duration: float, repeat: int, robot: Any, log) -> dict:
    """End-of-period projection on against off."""
    walls: dict[str, list[float]] = {'on': [], 'off': []}
    runs = {}
    for _ in range(repeat):
        for name in walls:
            integrator = replace(scene.simulator.integrator, projection=name == 'on')
            run = simulate(scene, duration, integrator, robot=robot)
            walls[name].append(run.wall)
            runs[name] = run
    on, off = runs['on'], runs['off']
    n = min(len(on.q), len(off.q))
    out = {'duration_s': duration, 'repeat': repeat, 'wall_s': walls,
           'median_on_s': _median(walls['on']), 'median_off_s': _median(walls['off']),
           'identical_q': bool(np.array_equal(on.q, off.q)),
           'max_q_difference': float(np.max(np.abs(on.q[:n] - off.q[:n]))),
           'max_head_difference_m': float(np.max(np.linalg.norm(on.head[:n] - off.head[:n],
                                                                axis=1))),
           'residual_on': on.residual, 'residual_off': off.residual,
           'status': [on.status, off.status]}
    out['saving_when_off'] = 1.0 - out['median_off_s'] / out['median_on_s']
    log(f'[projection] on {out["median_on_s"]:.2f} s, off {out["median_off_s"]:.2f} s '
        f'({100 * out["saving_when_off"]:.1f} % saved when off); results differ by '
        f'{out["max_q_difference"]:.2e} (q), {out["max_head_difference_m"]:.2e} m (head); '
        f'largest residual on {on.residual:.1e}, off {off.residual:.1e}')
    return out


def per_source_cost(scene: Scene, robot: Any, number: int, log) -> dict[str, float]:
    """Microseconds per evaluation of each control source at the initial observation: the
    native law with that source alone, its command built as the nodes send it."""
    from gait_manager.native import GaitManagerController
    from gait_manager.parameters import SOURCES
    from iceskate_bringup.scene import node_parameters
    from iceskate_sim.physics.native_control import native_observation, native_values

    obs = _obs(scene, robot)
    stack = ControlStack(scene, robot, obs)
    costs: dict[str, float] = {}
    if 'visual_lifting' in stack.controllers:
        lifting = stack.controllers['visual_lifting']
        costs['visual_lifting'] = _time_us(
            lambda: native_values(lifting, native_observation(obs), stack.kinematics), number)
    gm = node_parameters(scene).get('gait_manager')
    if gm is not None:
        for source in SOURCES:
            alone = GaitManagerController(replace(gm, enabled=frozenset({source})))
            costs[source] = _time_us(
                lambda c=alone: native_values(c, native_observation(obs), stack.kinematics),
                number)
    enabled = {s for sources in scene_sources(scene).values() for s in sources}
    log('[per source] us per evaluation: ' + ', '.join(
        f'{k} {v:.1f}{"" if k in enabled else " (disabled)"}' for k, v in costs.items()))
    return costs


def _time_us(func, number: int) -> float:
    func()
    return min(timeit.Timer(func).repeat(repeat=5, number=number)) / number * 1e6


def profile(scene: Scene, duration: float, out_dir: pathlib.Path, top: int, log) -> dict:
    """One pyinstrument profile of the headless runner on ``scene``."""
    from pyinstrument import Profiler

    from iceskate_bringup.runner import run
    profiler = Profiler(interval=0.0005)
    profiler.start()
    run(replace(scene, duration=duration), None, progress=False)
    profiler.stop()
    session = profiler.last_session
    own: dict[str, float] = {}
    total: dict[str, float] = {}

    def walk(frame, ancestors: frozenset) -> None:
        if frame.is_synthetic:  # '[self]' time: counted in the parent's total_self_time
            return
        key = f'{frame.function} ({frame.file_path_short}:{frame.line_no})'
        own[key] = own.get(key, 0.0) + frame.total_self_time
        if key not in ancestors:  # count recursive frames once
            total[key] = total.get(key, 0.0) + frame.time
        for child in frame.children:
            walk(child, ancestors | {key})

    root = session.root_frame()
    walk(root, frozenset())
    duration_s = session.duration
    html = out_dir / 'profile_stand.html'
    html.write_text(profiler.output_html())
    top_own = sorted(own.items(), key=lambda kv: -kv[1])[:top]
    top_total = sorted(total.items(), key=lambda kv: -kv[1])[:top * 2]
    log(f'[profile] {duration:g} s of stand, {duration_s:.2f} s profiled; HTML {html}')
    print(f'\nTop {top} by own time (share of {duration_s:.2f} s):')
    for key, t in top_own:
        print(f'  {100 * t / duration_s:5.1f} %  {t:6.2f} s  {key}')
    print(f'\nTop {2 * top} by total time (inclusive):')
    for key, t in top_total:
        print(f'  {100 * t / duration_s:5.1f} %  {t:6.2f} s  {key}')
    print()
    return {'duration_s': duration, 'profiled_s': duration_s,
            'top_own': [[k, t] for k, t in top_own],
            'top_total': [[k, t] for k, t in top_total], 'html': str(html)}


def markdown(figures: dict[str, Any]) -> str:
    """The figures as markdown tables."""
    r, p = figures['recording'], figures['projection']
    m = figures['machine']
    lines = ['# Laziness benchmark (stand scene)', '',
             f'Machine: {m["cpu"]}, {m["cpus"]} CPUs; {m["date"]}; load average at start '
             f'{m["loadavg_start"]}. Median of {r["repeat"]} runs.', '',
             '| skipping | on (s) | off (s) | saved | identical results |',
             '|---|---:|---:|---:|---|',
             f'| no bag (files only vs bag + files), {r["duration_s"]:g} s | '
             f'{r["median_total_s"]["files"]:.2f} | {r["median_total_s"]["bag"]:.2f} | '
             f'{100 * (1 - r["median_total_s"]["files"] / r["median_total_s"]["bag"]):.1f} % | '
             f'{r["identical_q_v_bag_vs_files"]} (q, v) |',
             f'| no output at all vs bag + files, {r["duration_s"]:g} s | '
             f'{r["median_total_s"]["none"]:.2f} | {r["median_total_s"]["bag"]:.2f} | '
             f'{100 * (1 - r["median_total_s"]["none"] / r["median_total_s"]["bag"]):.1f} % | '
             '- |',
             f'| projection off vs on, {p["duration_s"]:g} s | {p["median_off_s"]:.2f} | '
             f'{p["median_on_s"]:.2f} | {100 * p["saving_when_off"]:.1f} % | '
             f'{p["identical_q"]} (max diff q {p["max_q_difference"]:.1e}, residual off '
             f'{p["residual_off"]:.1e}) |', '',
             '| source | us per evaluation |', '|---|---:|']
    lines += [f'| {k} | {v:.1f} |' for k, v in figures['per_source_us'].items()]
    if 'profile' in figures:
        prof = figures['profile']
        lines += ['', f'Profile ({prof["duration_s"]:g} s of stand, {prof["profiled_s"]:.2f} s):',
                  '', '| own time | function |', '|---:|---|']
        lines += [f'| {100 * t / prof["profiled_s"]:.1f} % | `{k}` |' for k, t in prof['top_own']]
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Run the comparisons and the profile; write the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=pathlib.Path, default=REPO_ROOT / 'runs' / 'bench')
    parser.add_argument('--quick', action='store_true', help='short runs, one repeat')
    parser.add_argument('--repeat', type=int, help='runs per variant (default 3; quick 1)')
    parser.add_argument('--duration', type=float,
                        help='simulated seconds per run (default 3; quick 2.2: the stand push '
                        'ends at 2.1 s)')
    parser.add_argument('--top', type=int, default=15, help='profile entries to print')
    parser.add_argument('--no-profile', action='store_true')
    args = parser.parse_args(argv)
    repeat = args.repeat or (1 if args.quick else 3)
    duration = args.duration or (2.2 if args.quick else 3.0)
    started = time.perf_counter()

    def log(message: str) -> None:
        print(f'{time.perf_counter() - started:7.1f}s {message}', flush=True)

    args.out.mkdir(parents=True, exist_ok=True)
    robot = load_robot()
    scene = load_scene('stand')
    figures: dict[str, Any] = {'machine': machine_info(), 'scene': scene.name,
                               'enabled_sources': scene_sources(scene)}
    figures['per_source_us'] = per_source_cost(scene, robot, 200, log)
    figures['recording'] = compare_recording(scene, duration, repeat, log)
    figures['projection'] = compare_projection(scene, duration, repeat, robot, log)
    if not args.no_profile:
        figures['profile'] = profile(scene, duration, args.out, args.top, log)
    figures['machine']['benchmark_wall_s'] = time.perf_counter() - started
    (args.out / 'laziness.json').write_text(json.dumps(figures, indent=1, default=float) + '\n')
    table = markdown(figures)
    (args.out / 'laziness.md').write_text(table)
    print(table)
    ok = figures['recording']['identical_q_v_bag_vs_files']
    log(f'outputs in {args.out} (laziness.md, laziness.json, profile_stand.html); identical '
        f'results where expected: {ok}')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
