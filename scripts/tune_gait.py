"""Random search over the free gait parameters of model-spec §7/§14 (how the values were found).

Runs a base scene (default ``skate``) for a short time with sampled gait-manager parameters and
scores each run by the support exchanges made before a fall, then forward distance. Results go
to a JSON lines file, best first at the end.

    python scripts/tune_gait.py --scene skate --runs 40 --duration 6 --out runs/tune.jsonl
"""

from __future__ import annotations

import argparse
import copy
import json
import pathlib
import time

import numpy as np
import yaml

from iceskate_sim.errors import SimulationError
from iceskate_sim.runner import run
from iceskate_sim.scene import parse_scene, scene_dirs

# block.key -> (low, high): ranges around the spec's defaults (§7.1, §7.3, §13.2, §14)
SPACE = {
    'feedforward.hip_amplitude': (20.0, 60.0),
    'feedforward.hip_duration': (0.25, 0.5),
    'feedforward.knee_amplitude': (10.0, 30.0),
    'feedforward.knee_duration': (0.15, 0.35),
    'feedforward.ankle_push': (0.0, 40.0),
    'feedforward.knee_push': (0.0, 20.0),
    'weight_transfer.share': (0.6, 1.3),
    'weight_transfer.ramp_time': (0.2, 0.8),
    'weight_transfer.start_ramp': (0.2, 0.8),
    'posture.shift_y1': (0.0, 0.2),
    'posture.shift_z1': (0.0, 0.05),
    'posture.shift_time1': (0.3, 0.9),
    'posture.shift_y2': (0.0, 0.2),
    'posture.shift_time2': (0.2, 0.8),
    'posture.stiffness': (400.0, 1200.0),
    'posture.damping': (20.0, 120.0),
    'heel.landing_pitch': (0.05, 0.3),
}


def sample(rng: np.random.Generator) -> dict[str, float]:
    """One point of the search space."""
    return {key: float(rng.uniform(lo, hi)) for key, (lo, hi) in SPACE.items()}


def apply(raw: dict, point: dict[str, float]) -> dict:
    """The base scene with the sampled gait-manager parameters."""
    raw = copy.deepcopy(raw)
    gm = raw['inputs']['gait_manager']
    for key, value in point.items():
        block, name = key.split('.')
        gm.setdefault(block, {})[name] = value
    return raw


def score(metrics: dict) -> float:
    """Exchanges before the end, then forward distance (m) as a tie-breaker."""
    return metrics['steps'] + 0.1 * max(metrics.get('forward_distance_m', 0.0), 0.0)


def main() -> None:
    """Run the search."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scene', default='skate')
    parser.add_argument('--runs', type=int, default=40)
    parser.add_argument('--duration', type=float, default=6.0, help='simulated s per run')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--out', type=pathlib.Path, default=pathlib.Path('runs/tune.jsonl'))
    args = parser.parse_args()
    path = next(d / f'{args.scene}.yaml' for d in scene_dirs()
                if (d / f'{args.scene}.yaml').is_file())
    base = yaml.safe_load(path.read_text())
    base['duration'] = args.duration
    base['record'] = {'bag': False}
    rng = np.random.default_rng(args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    results = []
    with args.out.open('a') as log:
        for k in range(args.runs):
            point = sample(rng)
            start = time.perf_counter()
            try:
                metrics = run(parse_scene(apply(base, point)), None, progress=False)
            except SimulationError as exc:
                metrics = {'steps': 0, 'forward_distance_m': 0.0, 'failure': str(exc)}
            entry = {'run': k, 'score': score(metrics), 'steps': metrics['steps'],
                     'forward_distance_m': metrics.get('forward_distance_m'),
                     'sim_time_s': metrics.get('sim_time_s'), 'failure': metrics.get('failure'),
                     'wall_s': time.perf_counter() - start, 'params': point}
            results.append(entry)
            log.write(json.dumps(entry) + '\n')
            log.flush()
            print(f"run {k}: score {entry['score']:.2f} steps {entry['steps']} "
                  f"t {entry['sim_time_s']} ({entry['failure']})", flush=True)
    best = max(results, key=lambda e: e['score'])
    print(json.dumps(best, indent=1))


if __name__ == '__main__':
    main()
