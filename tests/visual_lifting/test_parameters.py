"""VisualLiftingParameters, the one schema of the law's parameters: defaults, the rules of
every field, every field reaching the C++ law by its name, and the binding refusing what C++
cannot take, in one sentence naming the field."""

from dataclasses import asdict
import math
from types import SimpleNamespace

import pytest

from iceskate_native.parameters import flatten, leaf_fields
from visual_lifting.errors import VisualLiftingError
from visual_lifting.native import VisualLiftingController
from visual_lifting.parameters import VisualLiftingParameters


def test_defaults_follow_the_model():
    p = VisualLiftingParameters()
    assert p.kp == (20.0, 290.0, 1100.0)
    assert p.joints == (1, 2, 3, 4, 8, 9, 10, 17)
    assert p.joint1_torque is True and p.desired_y == 'moving'
    assert p.v_d == 0.3 and p.z_d is None and p.pitch_d == 0.0 and p.max_dy == 0.3
    assert (p.shift_y1, p.shift_z1, p.shift_y2) == (0.0, 0.0, 0.0)


def test_from_dict_accepts_yaml_like_values():
    p = VisualLiftingParameters.from_dict({'kp': [10, 100, 500], 'joints': [2, 3], 'z_d': 1.6,
                                           'desired_y': 'follow', 'max_dy': None})
    assert p.kp == (10.0, 100.0, 500.0) and p.joints == (2, 3) and p.max_dy is None
    assert VisualLiftingParameters.from_dict({}) == VisualLiftingParameters()


@pytest.mark.parametrize(('key', 'value'), [
    ('kp', [1.0, 2.0]), ('kp', [1.0, -2.0, 3.0]), ('kp', 'abc'), ('kp', [1, 2, math.nan]),
    ('joints', [0, 2]), ('joints', [2, 2]), ('joints', [2.5]), ('joints', [True]),
    ('joint1_torque', 'yes'), ('desired_y', 'forward'), ('v_d', '0.3'), ('v_d', math.inf),
    ('z_d', 0.0), ('z_d', -1.0), ('pitch_d', None), ('max_dy', 0.0), ('max_dy', True),
    ('shift_y1', 1.0), ('shift_time2', -0.1),
])
def test_from_dict_rejects_bad_values_naming_the_key(key, value):
    with pytest.raises(VisualLiftingError, match=f'^{key} '):
        VisualLiftingParameters.from_dict({key: value})


def test_from_dict_rejects_unknown_keys():
    with pytest.raises(VisualLiftingError, match='kd'):
        VisualLiftingParameters.from_dict({'kd': [1, 2, 3]})
    with pytest.raises(VisualLiftingError):
        VisualLiftingParameters.from_dict([('kp', (1, 2, 3))])
    assert issubclass(VisualLiftingError, ValueError)


def _as_python(values: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}


def test_every_field_reaches_the_cpp_law_by_its_name():
    """Each field, set to its own value (the numbers all different), comes back from the C++
    struct the law reads (``VisualLiftingController.parameters``) under its own name, and the
    struct holds exactly the dataclass's fields."""
    params = VisualLiftingParameters(
        kp=(21.0, 291.0, 1101.0), joints=(17, 2, 9), joint1_torque=False, desired_y='fixed',
        v_d=-0.35, z_d=1.55, pitch_d=0.07, max_dy=0.25, shift_y1=0.11, shift_z1=0.031,
        shift_time1=0.61, shift_y2=0.12, shift_time2=0.52)
    default = flatten(VisualLiftingParameters())
    for name, value in flatten(params).items():
        assert value != default[name], name
    numbers = [v for v in flatten(params).values() if isinstance(v, float)]
    assert len(set(numbers)) == len(numbers)
    held = VisualLiftingController(params).parameters
    assert held == _as_python(asdict(params))
    assert set(held) == set(leaf_fields(VisualLiftingParameters))
    unset = VisualLiftingController(VisualLiftingParameters(max_dy=None)).parameters
    assert unset['max_dy'] is None and unset['z_d'] is None
    controller = VisualLiftingController(VisualLiftingParameters())
    assert controller.parameters == _as_python(asdict(VisualLiftingParameters()))
    controller.set_parameters(params)
    assert controller.parameters == held


def _fields(**changes) -> SimpleNamespace:
    """The fields of the default parameters with ``changes``, unchecked by the dataclass."""
    return SimpleNamespace(**{**asdict(VisualLiftingParameters()), **changes})


@pytest.mark.parametrize(('changes', 'message'), [
    ({'kp': (1.0, 2.0)}, 'kp has 2 entries, expected 3'),
    ({'kp': (1.0, float('nan'), 2.0)}, 'kp has a non-finite entry'),
    ({'v_d': float('nan')}, 'v_d is nan: every parameter must be finite'),
    ({'z_d': float('inf')}, 'z_d is inf: every parameter must be finite'),
    ({'joints': (1, 18)}, 'joints holds joint 18, expected joints 1-17'),
    ({'desired_y': 'sideways'}, "desired_y 'sideways' is not one of moving, follow, fixed"),
    ({'joint1_torque': 1}, 'joint1_torque must be true or false'),
    ({'v_d': 'fast'}, 'v_d must be a number'),
    ({'shift_time2': float('inf')}, 'shift_time2 is inf'),
])
def test_the_binding_refuses_bad_parameters_in_one_sentence(changes, message):
    with pytest.raises(ValueError, match=f'^{message}'):
        VisualLiftingController(_fields(**changes))
    fields = _fields()
    del fields.pitch_d
    with pytest.raises(ValueError, match='^the parameters have no field pitch_d$'):
        VisualLiftingController(fields)
