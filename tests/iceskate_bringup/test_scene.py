"""Scenes: every shipped scene validates; malformed scenes are refused naming the key."""

import copy

import pytest

from iceskate_bringup.scene import controller_parameters, load_scene, parse_scene, scene_sources
from iceskate_sim.errors import SimulationError
from iceskate_sim.installed import shipped_files
from iceskate_sim.run.scene import SCENE_RESOURCE, scene_raw

REQUIRED = {'stand', 'stand_ice', 'skate', 'skate_glide', 'skate_literal', 'skate_no_yaw', 'walk',
            'walk_slippery'}


def _raw(name: str) -> dict:
    return scene_raw(name)


def test_required_scenes_are_shipped():
    assert REQUIRED <= set(shipped_files(SCENE_RESOURCE, 'scenes'))


@pytest.mark.parametrize('name', sorted(REQUIRED))
def test_every_shipped_scene_validates(name):
    scene = load_scene(name)
    assert scene.name == name
    assert scene.duration > 0 and scene.simulator.control_period > 0


def test_skate_and_skate_no_yaw_differ_only_by_the_yaw_input():
    skate, no_yaw = _raw('skate'), _raw('skate_no_yaw')
    assert 'yaw' in scene_sources(load_scene('skate'))['gait_manager']
    assert 'yaw' not in scene_sources(load_scene('skate_no_yaw'))['gait_manager']
    for raw in (skate, no_yaw):
        raw.pop('scene'), raw.pop('description')
        raw['inputs']['gait_manager']['enabled'] = sorted(
            set(raw['inputs']['gait_manager']['enabled']) - {'yaw'})
    assert skate == no_yaw


def test_skate_and_skate_literal_differ_only_by_the_reading_of_eq_10():
    skate, literal = _raw('skate'), _raw('skate_literal')
    for name, reading in (('skate', 'B'), ('skate_literal', 'A')):
        block = load_scene(name).inputs['gait_manager']
        assert controller_parameters('gait_manager', block).yaw.phase == reading
    for raw in (skate, literal):
        raw.pop('scene'), raw.pop('description')
        raw['inputs']['gait_manager'].setdefault('yaw', {}).pop('phase', None)
    assert skate == literal


def test_skate_is_on_ice_and_walk_on_a_normal_floor():
    assert load_scene('skate').simulator.friction.rule == 'ice'
    assert load_scene('skate').simulator.friction.mu == 0.005
    assert load_scene('walk').simulator.friction.rule == 'coulomb'
    assert load_scene('walk').simulator.friction.mu == 0.8


def test_stand_runs_only_what_it_declares():
    assert scene_sources(load_scene('stand')) == {'visual_lifting': ('visual_lifting',),
                                                  'gait_manager': ('posture', 'weight_transfer')}


@pytest.mark.parametrize(('path', 'value', 'match'), [
    (('integrator', 'stepp'), 1e-3, r'integrator\.stepp.*unknown key'),
    (('integrator', 'step'), 'fast', r'integrator\.step.*number'),
    (('integrator', 'step'), -1e-3, r'integrator\.step.*must be >= 1e-06'),
    (('integrator', 'step'), 1e-9, r'integrator\.step.*must be >= 1e-06, got 1e-09'),
    (('integrator', 'method'), 'euler', r'integrator\.method.*one of'),
    (('floor', 'mu'), -0.1, r'floor\.mu.*must be in \[0, 2\]'),
    (('floor', 'rule'), 'sand', r'floor\.rule'),
    (('initial', 'mode'), 21, r'initial\.mode.*must be in \[1, 20\]'),
    (('initial', 'q'), {'q42': 0.1}, r'initial\.q\.q42.*unknown key'),
    (('duration',), float('nan'), r'duration.*finite'),
    (('inputs', 'gait_manager', 'posture', 'stiffness'), -5.0, r'posture\.stiffness'),
    (('inputs', 'visual_lifting', 'kp'), [1.0, 2.0], r'inputs\.visual_lifting'),
    (('colour',), 'blue', r'colour.*unknown key'),
    (('engine',), 'python', r"'engine': the physics always runs on the native core now"),
    (('record', 'rate'), 300.0, r'record\.rate.*300 samples/s does not divide the control rate'),
    (('record', 'rate'), 0.0, r'record\.rate'),
    (('record', 'rate'), 2000.0, r'record\.rate.*does not divide'),
    (('record', 'tf_rate'), 0.0, r'record\.tf_rate'),
    (('record', 'bag_rate'), -250.0, r'record\.bag_rate'),
    (('record', 'bag_rate'), [250], r'record\.bag_rate'),
    (('record', 'tf_rate'), 'fast', r'record\.tf_rate'),
])
def test_a_malformed_scene_is_refused_naming_the_key(path, value, match):
    raw = copy.deepcopy(_raw('skate'))
    node = raw
    for key in path[:-1]:
        node = node.setdefault(key, {})
    node[path[-1]] = value
    with pytest.raises(SimulationError, match=match):
        parse_scene(raw)


def test_record_rate_is_a_divisor_of_the_control_rate():
    raw = copy.deepcopy(_raw('skate'))
    assert parse_scene(raw).record_every == 1
    raw['record'] = {'rate': 250}
    assert parse_scene(raw).record_every == 4


@pytest.mark.parametrize('record, bag_every, tf_every', [
    ({}, 4, 2),                             # 1 kHz samples: the bag 250 Hz, /tf 125 Hz
    ({'tf_rate': None}, 4, 1),              # /tf at every sample of the bag
    ({'bag_rate': None}, 1, 10),            # every sample, /tf at 100 Hz
    ({'bag_rate': None, 'tf_rate': 300}, 1, 3),  # 333 Hz: the lowest rate of at least 300
    ({'bag_rate': 300}, 3, 3),              # the bag 333 Hz, /tf 111 Hz
    ({'bag_rate': None, 'tf_rate': 1000}, 1, 1),
    ({'bag_rate': 5000, 'tf_rate': 5000}, 1, 1),  # no more than the samples
    ({'rate': 250}, 1, 2),                  # 250 Hz recorded: all in the bag, /tf 125 Hz
    ({'rate': 50}, 1, 1),
])
def test_the_bags_rates_are_at_least_the_ones_asked(record, bag_every, tf_every):
    raw = copy.deepcopy(_raw('skate'))
    raw['record'] = record
    scene = parse_scene(raw)
    assert (scene.bag_every, scene.tf_every) == (bag_every, tf_every)


def test_control_period_must_be_a_multiple_of_the_step():
    raw = copy.deepcopy(_raw('stand'))
    raw['integrator']['step'] = 0.0007
    with pytest.raises(SimulationError, match='control_period.*integer multiple'):
        parse_scene(raw)


def test_malformed_yaml_and_unknown_scene_are_refused(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('scene: [unclosed\n')
    with pytest.raises(SimulationError, match='malformed YAML'):
        load_scene(bad)
    with pytest.raises(SimulationError, match="unknown scene 'nope'"):
        load_scene('nope')


def test_a_base_chain_merges_in_order_and_a_loop_is_refused(tmp_path):
    (tmp_path / 'a.yaml').write_text('base: stand\nscene: a\nfloor: {mu: 0.3}\n')
    (tmp_path / 'b.yaml').write_text('base: a.yaml\nscene: b\nduration: 1.5\n')
    raw = scene_raw(tmp_path / 'b.yaml', {'floor.rule': 'ice'})
    assert (raw['scene'], raw['duration'], raw['floor']) == ('b', 1.5, {'rule': 'ice', 'mu': 0.3})
    assert raw['inputs'] == scene_raw('stand')['inputs']
    (tmp_path / 'a.yaml').write_text('base: b.yaml\nscene: a\n')
    with pytest.raises(SimulationError, match="a.yaml: its base 'b.yaml' leads back to itself"):
        scene_raw(tmp_path / 'b.yaml')
    (tmp_path / 'c.yaml').write_text('base: [stand]\nscene: c\n')
    with pytest.raises(SimulationError, match='base must be a shipped scene name or the path'):
        scene_raw(tmp_path / 'c.yaml')
    (tmp_path / 'd.yaml').write_text('base: nowhere\nscene: d\n')
    with pytest.raises(SimulationError, match="unknown scene 'nowhere'"):
        scene_raw(tmp_path / 'd.yaml')


def test_every_key_of_a_shipped_scene_has_its_rules_in_a_schema():
    """``key_rules``: the description and unit of a scene key, from the class declaring it."""
    from iceskate_bringup.scene import key_rules

    def leaves(node: dict, prefix: str = '') -> list[str]:
        return [key for name, value in node.items()
                for key in (leaves(value, f'{prefix}{name}.') if isinstance(value, dict)
                            else [f'{prefix}{name}'])]
    keys = [k for k in leaves(_raw('skate'))
            if not k.startswith(('disturbances', 'initial.q.', 'initial.v.'))]
    assert len(keys) > 40
    missing = [k for k in keys if key_rules(k) is None]
    assert not missing, missing
    assert key_rules('record.tf_rate').unit == '1/s'
    assert key_rules('inputs.visual_lifting.kp').unit == 'N/m, N/m, N m/rad'
    assert key_rules('inputs.knees.gain') is None and key_rules('floor.nothing') is None
