"""The native kernel (iceskate_native._kernel, C++ on Pinocchio's C++ API, nanobind bindings).

Needs the built workspace (``make setup``; ``. ./env.sh`` puts it on the path). The models are
the ones Python builds (iceskate_sim.model.robot), handed to C++ as Pinocchio's binary archive.
"""

import itertools
import math

import numpy as np
import pinocchio as pin
import pytest

import iceskate_native
from iceskate_native import NativeError, RobotModel, crba_of
from iceskate_sim.model.robot import PIVOTS, SIDES, load_robot

SEED = 20190605
DRAWS = 20
SUPPORTS = list(itertools.product(SIDES, PIVOTS))


@pytest.fixture(scope='module')
def robot():
    return load_robot()


@pytest.fixture(scope='module')
def right_toe(robot):
    model = robot.support_model('right', 'toe').model
    return model, iceskate_native.load_model(model)


def test_the_module_is_the_built_extension():
    kernel = iceskate_native._kernel
    assert kernel.__file__.endswith('.so'), kernel.__file__
    assert 'ros_ws/install/iceskate_native/' in kernel.__file__


@pytest.mark.parametrize(('side', 'pivot'), SUPPORTS)
def test_the_model_crosses_whole(robot, side, pivot):
    model = robot.support_model(side, pivot).model
    native = iceskate_native.load_model(model)
    assert (native.nq, native.nv, native.njoints, native.name) == (
        model.nq, model.nv, model.njoints, model.name)
    assert repr(native) == f"RobotModel(name='{model.name}', nq={model.nq}, nv={model.nv})"


@pytest.mark.parametrize(('side', 'pivot'), SUPPORTS)
def test_crba_equals_python_pinocchio(robot, side, pivot):
    model = robot.support_model(side, pivot).model
    native = iceskate_native.load_model(model)
    data = model.createData()
    rng = np.random.default_rng(SEED)
    for _ in range(DRAWS):
        q = rng.uniform(-math.pi, math.pi, model.nq)
        expected = pin.crba(model, data, q).copy()
        expected = np.triu(expected) + np.triu(expected, 1).T
        actual = crba_of(native, q)
        assert actual.shape == (model.nv, model.nv)
        assert actual.dtype == np.float64
        np.testing.assert_array_equal(actual, actual.T)
        scale = max(1.0, float(np.max(np.abs(expected))))
        error = float(np.max(np.abs(actual - expected)))
        assert error <= 1e-12 * scale, f'{side}/{pivot}: max error {error:.3e} at q={q}'


def test_crba_converts_arrays_and_takes_the_archive_bytes(right_toe):
    model, native = right_toe
    q = np.linspace(-0.5, 0.5, model.nq)
    reference = crba_of(native, q)
    wide = np.zeros(2 * model.nq)
    wide[::2] = q
    np.testing.assert_array_equal(crba_of(native, wide[::2]), reference)  # strided
    np.testing.assert_array_equal(crba_of(native, np.zeros(model.nq, dtype=int)),
                                  crba_of(native, np.zeros(model.nq)))  # int -> float64
    np.testing.assert_array_equal(crba_of(iceskate_native.model_bytes(model), q), reference)


@pytest.mark.parametrize('length', [0, 17, 19])
def test_a_wrong_length_q_is_refused(right_toe, length):
    _, native = right_toe
    with pytest.raises(ValueError, match=rf'q has {length} entries, expected 18 \(model nq\)'):
        crba_of(native, np.zeros(length))


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_a_non_finite_q_is_refused(right_toe, bad):
    _, native = right_toe
    q = np.zeros(18)
    q[5] = bad
    with pytest.raises(ValueError, match=r'q\[5\] is -?(nan|inf): every entry must be finite'):
        crba_of(native, q)


def test_a_q_of_another_shape_or_type_is_refused(right_toe):
    _, native = right_toe
    with pytest.raises(TypeError):
        crba_of(native, np.zeros((18, 1)))
    with pytest.raises(TypeError):
        crba_of(native, 'q')
    with pytest.raises(TypeError):  # arrays only: nanobind does not convert a list
        crba_of(native, [0.0] * 18)
    with pytest.raises(TypeError):
        crba_of(None, np.zeros(18))


@pytest.mark.parametrize('data', [b'', b'garbage', b'22 serialization::archive 20 0 0 18'])
def test_bytes_that_are_no_model_are_refused(data):
    with pytest.raises(ValueError, match='model bytes'):
        RobotModel.from_bytes(data)


def test_a_truncated_archive_is_refused(right_toe):
    model, _ = right_toe
    data = iceskate_native.model_bytes(model)
    for cut in (len(data) // 3, len(data) - 1):
        with pytest.raises(ValueError, match='model bytes'):
            RobotModel.from_bytes(data[:cut])


def test_native_error_is_a_runtime_error():
    assert issubclass(NativeError, RuntimeError)
    assert NativeError.__module__ in ('iceskate_native', 'iceskate_native._kernel')
