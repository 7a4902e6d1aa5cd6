"""The native kernel (iceskate_native._kernel, C++ on Pinocchio's C++ API, nanobind bindings).

Needs the built workspace (``make setup``; ``. ./env.sh`` puts it on the path). The models are
the ones Python builds (iceskate_sim.model.robot), handed to C++ as Pinocchio's binary archive.
"""

import itertools

import pytest

import iceskate_native
from iceskate_native import NativeError, RobotModel
from iceskate_sim.model.robot import PIVOTS, SIDES, load_robot

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
