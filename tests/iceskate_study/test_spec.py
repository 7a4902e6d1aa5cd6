"""SPEC files: validation (each refusal names its key), axes, sampling, keys of runs."""

import copy

import numpy as np
import pytest

from hostile import alias_bomb
from iceskate_bringup.runner import simulate
from iceskate_bringup.scene import load_scene, parse_scene
from iceskate_sim.installed import shipped_files
from iceskate_sim.run.metrics import METRIC_NAMES, METRICS
from iceskate_study.errors import StudyError
from iceskate_study.spec import STUDY_RESOURCE, expand, load_spec, parse_spec, run_key, set_key


def shipped_studies():
    """Names of the shipped studies."""
    return list(shipped_files(STUDY_RESOURCE, 'studies'))


@pytest.fixture
def make(tmp_path, grid):
    """``make(**changes)``: the grid SPEC with top-level keys changed (None: removed)."""

    def spec(**changes):
        raw = copy.deepcopy(grid)
        for key, value in changes.items():
            if value is None:
                raw.pop(key, None)
            else:
                raw[key] = value
        return parse_spec(raw, tmp_path / 'spec.yaml')

    return spec


@pytest.mark.parametrize(('axes', 'message'), [
    ({'floor.muu': [0.01]}, r"SPEC key 'axes.floor.muu': the value 0.01 gives a bad scene: "
                            r"scene key 'floor.muu': unknown key"),
    ({'floor..mu': [0.01]}, r"SPEC key 'axes.floor..mu': 'floor..mu' is not a dotted scene key"),
    ({'inputs.gait_manager.yaw.amplitud': [1.0]}, r"axes.inputs.gait_manager.yaw.amplitud'.*"
                                                  r'unknown key yaw.amplitud'),
    ({'disturbances[0].force[1]': [10.0]}, r'disturbances is not in the scene; give the whole '
                                           r'list in overrides first'),
])
def test_a_bad_key_is_refused_naming_it(make, axes, message):
    with pytest.raises(StudyError, match=message):
        make(axes=axes)


@pytest.mark.parametrize(('axis', 'message'), [
    ({'linspace': [0.001, 0.01, 0]}, r"'axes.floor.mu.linspace': the count of values must be an "
                                     r'integer in \[1, 1000000\], got 0'),
    ({'linspace': [0.001, 0.02, 100_000_000]}, r'integer in \[1, 1000000\], got 100000000'),
    ({'linspace': [0.001, 0.01]}, r"'axes.floor.mu.linspace': must be \[start, stop, count\]"),
    ({'logspace': [0.0, 0.01, 3]}, r"'axes.floor.mu.logspace': start and stop must be > 0"),
    ({'linspace': [0.01, 0.01, 3]}, r'start and stop are equal'),
    ({'linspace': [0.0, 5.0, 3]}, r"'axes.floor.mu': the value 2.5 gives a bad scene: scene key "
                                  r"'floor.mu': must be in \[0, 2\], got 2.5"),
    ({'range': [0.0, 0.01]}, r"'axes.floor.mu': a range is sampled"),
    ({'steps': 3}, r"'axes.floor.mu': an axis is a list of values"),
])
def test_a_bad_range_is_refused_naming_the_axis(make, axis, message):
    with pytest.raises(StudyError, match=message):
        make(axes={'floor.mu': axis})


def test_an_alias_bomb_in_a_spec_is_refused_before_anything_is_built(tmp_path):
    """In a study's overrides (or an axis): one sentence, fast (the bound of every YAML read)."""
    spec = tmp_path / 'bomb.yaml'
    spec.write_text(f'scene: skate\noverrides:\n  description: {alias_bomb()}\n'
                    'axes:\n  floor.mu: [0.01]\n')
    with pytest.raises(StudyError, match=f'SPEC {spec} expands to more than 100000 values'):
        load_spec(spec)


def test_a_spec_of_too_many_runs_is_refused_before_any_scene_is_made(make):
    """Two axes of 1,000 values each: a million points, refused at once (counted, not made)."""
    with pytest.raises(StudyError, match=r"'axes': the SPEC generates 2000000 runs, more than "
                                         r'1000000'):
        make(axes={'floor.mu': {'linspace': [0.001, 0.01, 1000]},
                   'inputs.gait_manager.yaw.amplitude': {'linspace': [0.0, 30.0, 1000]}},
             repeats=2)


def test_an_empty_axis_is_refused(make):
    with pytest.raises(StudyError, match=r"SPEC key 'axes.floor.mu': an axis needs at least one "
                                         r'value, got \[\]'):
        make(axes={'floor.mu': []})
    with pytest.raises(StudyError, match=r"SPEC key 'axes': must map at least one scene key"):
        make(axes={})


@pytest.mark.parametrize(('changes', 'message'), [
    ({'scene': 'rink'}, r"SPEC key 'scene': unknown scene 'rink'"),
    ({'study': None}, r"SPEC key 'study': must be given"),
    ({'repeat': 2}, r"SPEC key 'repeat': unknown key"),
    ({'repeats': 0}, r"SPEC key 'repeats': must be >= 1, got 0"),
    ({'repeats': 1.5}, r"SPEC key 'repeats': must be an integer, got 1.5"),
    ({'sampling': 'random'}, r"SPEC key 'samples': must be given for sampling 'random'"),
    ({'overrides': {'duration': -1.0}}, r"SPEC key 'overrides': the base scene with the "
                                        r"overrides gives a bad scene: scene key 'duration'"),
    ({'metrics': ['arm_swings']}, r"SPEC key 'metrics': 'arm_swings' is not in metrics.json"),
    ({'sampling': 'sobol'}, r"SPEC key 'sampling': must be one of"),
    ({'seed': 3}, r"SPEC key 'seed': is for sampling 'random' or 'latin_hypercube'"),
    ({'maps': {'x': 'floor.mu', 'y': 'duration'}}, r"SPEC key 'maps.y': 'duration' is not an "
                                                   r'axis'),
    ({'ratios': {'r': {'metric': 'steps', 'baseline': {'floor.mu': 0.02}}}},
     r"SPEC key 'ratios.r.baseline': 0.02 is not a value of axis 'floor.mu'"),
    ({'ratios': {'r': {'metric': 'arm_swing.corr_q11_q14', 'baseline': {'floor.mu': 0.01}}}},
     r"'arm_swing.corr_q11_q14' is not among the metrics kept"),
    ({'metrics': ['arm_swing'], 'ratios': {'arm_swing_ratio': {
        'metric': 'arm_swing.q11_peak_to_peak', 'baseline': {'floor.mu': 0.01}}}},
     r"SPEC key 'ratios.arm_swing_ratio.metric': arm_swing_ratio is the ratio of "
     r"arm_swing.mean_peak_to_peak"),
    ({'ratios': {'steps': {'metric': 'fell', 'baseline': {'floor.mu': 0.01}}}},
     r"SPEC key 'ratios.steps': the name is already a column"),
    ({'ratios': {'edge_mode_fraction': {'metric': 'steps', 'baseline': {'floor.mu': 0.01}}}},
     r"SPEC key 'ratios.edge_mode_fraction': 'edge_mode_fraction' is a metric of metrics.json"),
    ({'ratios': {'r': {'baseline': {'floor.mu': 0.01}}}}, r"SPEC key 'ratios.r': must be "),
    ({'bags': [{'floor.mu': 0.3}]}, r"SPEC key 'bags\[0\]': selects no point"),
    ({'bags': [{'duration': 1.0}]}, r"SPEC key 'bags\[0\].duration': not an axis"),
])
def test_a_bad_spec_is_refused_naming_the_key(make, changes, message):
    with pytest.raises(StudyError, match=message):
        expand(make(**changes))


def test_the_arm_swing_ratio_is_the_registry_s_by_its_name(make):
    """A ratio named as the registry's arm_swing_ratio needs no metric: it is that one."""
    spec = make(metrics=['fell', 'arm_swing'], ratios={'arm_swing_ratio': {
        'baseline': {'inputs.gait_manager.yaw.amplitude': 0.0}}})
    assert spec.ratios[0].metrics == METRICS['arm_swing_ratio'].ratio_of


def test_a_grid_makes_every_combination_first_axis_slowest(make):
    points = expand(make(repeats=2))
    assert [(p.index, p.repeat) for p in points] == [(i, r) for i in range(4) for r in range(2)]
    assert [tuple(p.values.values()) for p in points[::2]] == [
        (0.005, 0.0), (0.005, 30.0), (0.01, 0.0), (0.01, 30.0)]
    first = points[2].raw
    assert first['floor']['mu'] == 0.005 and first['floor']['rule'] == 'ice'
    assert first['inputs']['gait_manager']['yaw'] == {'amplitude': 30.0}
    assert first['duration'] == 0.5 and first['record'] == {'bag': False}
    assert len({p.key for p in points}) == len(points)  # repeats have keys of their own


def test_the_key_is_a_hash_of_the_scene_and_the_repeat(make):
    a, b = expand(make()), expand(make())
    assert [p.key for p in a] == [p.key for p in b]
    assert a[0].key == run_key(a[0].raw, 0) != run_key(a[0].raw, 1)
    other = copy.deepcopy(a[0].raw)
    other['duration'] = 0.6
    assert run_key(other, 0) != a[0].key


@pytest.mark.parametrize('sampling', ['random', 'latin_hypercube'])
def test_sampling_draws_in_the_ranges_with_its_seed(make, sampling):
    axes = {'floor.mu': {'range': [0.002, 0.02], 'scale': 'log'},
            'inputs.gait_manager.yaw.amplitude': {'range': [0.0, 40.0]}}
    spec = make(axes=axes, sampling=sampling, samples=8, seed=4)
    values = np.array([list(p.values.values()) for p in expand(spec)])
    assert values.shape == (8, 2)
    assert np.all((values[:, 0] >= 0.002) & (values[:, 0] <= 0.02))
    assert np.all((values[:, 1] >= 0.0) & (values[:, 1] <= 40.0))
    again = np.array([list(p.values.values()) for p in expand(spec)])
    assert np.array_equal(values, again)
    other = make(axes=axes, sampling=sampling, samples=8, seed=5)
    assert not np.array_equal(values, [list(p.values.values()) for p in expand(other)])
    if sampling == 'latin_hypercube':  # one sample in each eighth of each (log) range
        for column, (low, high) in ((np.log(values[:, 0]), np.log([0.002, 0.02])),
                                    (values[:, 1], (0.0, 40.0))):
            bins = np.floor((column - low) / (high - low) * 8).astype(int)
            assert sorted(bins) == list(range(8))


def test_logspace_and_indexed_keys(tmp_path):
    spec = parse_spec({'study': 'push', 'scene': 'stand', 'overrides': {'duration': 0.2},
                       'axes': {'disturbances[0].force[1]': {'logspace': [10.0, 1000.0, 3]},
                                'inputs.visual_lifting.kp': [[30.0, 290.0, 1100.0]]}},
                      tmp_path / 'spec.yaml')
    points = expand(spec)
    assert [p.raw['disturbances'][0]['force'] for p in points] == [
        [0.0, 10.0, 0.0], [0.0, pytest.approx(100.0), 0.0], [0.0, 1000.0, 0.0]]
    with pytest.raises(StudyError, match=r"'axes.x': x is not in the scene; give the whole list"):
        set_key({}, 'x[0]', 1.0, 'axes.x')


def test_the_shipped_study_is_valid():
    assert 'arm_swing' in shipped_studies()
    spec = load_spec('arm_swing')
    points = expand(spec)
    assert len(points) == 99
    amplitudes = sorted({p.values['inputs.gait_manager.yaw.amplitude'] for p in points})
    frictions = sorted({p.values['floor.mu'] for p in points})
    assert amplitudes[0] == 0.0 and amplitudes[-1] == 40.0
    assert frictions[0] == pytest.approx(0.002) and frictions[-1] == pytest.approx(0.02)
    assert all(p.raw['duration'] == 15.0 for p in points)


def test_the_shipped_push_study_pushes_once_every_half_push_length_both_ways():
    assert 'push_robustness' in shipped_studies()
    points = expand(load_spec('push_robustness'))
    assert len(points) == 644
    pushes = [p.raw['disturbances'] for p in points]
    assert all(len(d) == 1 and d[0]['frame'] == 'chest' and d[0]['duration'] == 0.1
               for d in pushes)
    starts = sorted({d[0]['start'] for d in pushes})
    assert starts[0] == 4.0 and starts[-1] == 12.0 and np.allclose(np.diff(starts), 0.05)
    assert sorted({tuple(d[0]['force']) for d in pushes}) == [
        (0.0, force, 0.0) for force in (-150.0, -75.0, 75.0, 150.0)]
    assert all(p.raw['duration'] == 15.0 for p in points)


def test_the_shipped_endurance_study_walks_a_minute_over_the_friction_range():
    assert 'endurance' in shipped_studies()
    points = expand(load_spec('endurance'))
    assert len(points) == 34
    frictions = sorted({p.values['floor.mu'] for p in points})
    assert len(frictions) == 17
    assert frictions[0] == pytest.approx(0.002) and frictions[-1] == pytest.approx(0.02)
    assert sorted({p.values['inputs.gait_manager.yaw.amplitude'] for p in points}) == [0.0, 30.0]
    assert all(p.raw['duration'] == 60.0 for p in points)


def test_metric_names_are_the_entries_of_metrics_json():
    scene = parse_scene({**load_scene('stand').raw, 'duration': 0.05, 'record': {'bag': False},
                         'disturbances': [{'start': 0.0, 'duration': 0.01, 'frame': 'chest',
                                           'force': [0.0, 1.0, 0.0]}]})
    outcome = simulate(scene, None, progress=False)
    metrics, error = outcome.metrics, outcome.error
    assert error is None
    assert set(metrics) == set(METRIC_NAMES)
