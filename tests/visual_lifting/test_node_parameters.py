"""The controller nodes' typed ROS parameters: listed with type, unit and range, changed at run
time through the parameter classes' own rules (what ``ros2 param set`` does)."""

import math

import pytest

pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros]

from rcl_interfaces.msg import ParameterType  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from gait_manager.gait_manager_node import GaitManagerNode  # noqa: E402
from gait_manager.parameters import GaitManagerParameters  # noqa: E402
from iceskate_native.parameters import leaf_fields  # noqa: E402
from visual_lifting.parameters import VisualLiftingParameters  # noqa: E402
from visual_lifting.visual_lifting_node import VisualLiftingNode  # noqa: E402


@pytest.fixture
def visual_lifting_node(ros_context):
    node = VisualLiftingNode(context=ros_context)
    try:
        yield node
    finally:
        node.destroy_node()


def test_every_field_is_a_typed_parameter_with_its_description(visual_lifting_node):
    node = visual_lifting_node
    for name, (_, rules, _) in leaf_fields(VisualLiftingParameters).items():
        assert node.has_parameter(name), name
        (descriptor,) = node.describe_parameters([name])
        assert descriptor.description.startswith(rules.description), name
    (kp,) = node.describe_parameters(['kp'])
    assert kp.type == ParameterType.PARAMETER_DOUBLE_ARRAY and '[N/m, N/m, N m/rad]' in \
        kp.description
    (v_d,) = node.describe_parameters(['v_d'])
    assert v_d.type == ParameterType.PARAMETER_DOUBLE
    assert (v_d.floating_point_range[0].from_value, v_d.floating_point_range[0].to_value) == \
        (-5.0, 5.0)
    assert math.isnan(node.get_parameter('z_d').value)  # unset optional: NaN
    assert node.params == VisualLiftingParameters()


def test_a_change_goes_through_the_rules(visual_lifting_node):
    node = visual_lifting_node
    (result,) = node.set_parameters([Parameter('kp', value=[30.0, 290.0, 1100.0])])
    assert result.successful and node.params.kp == (30.0, 290.0, 1100.0)
    (result,) = node.set_parameters([Parameter('kp', value=[30.0, 290.0])])
    assert not result.successful and result.reason == 'kp must have 3 entries, got 2'
    (result,) = node.set_parameters([Parameter('joints', value=[1, 2, 2])])
    assert not result.successful and 'joints must not repeat an entry' in result.reason
    (result,) = node.set_parameters([Parameter('desired_y', value='sideways')])
    assert not result.successful and 'desired_y must be one of' in result.reason
    (result,) = node.set_parameters([Parameter('z_d', value=1.5)])
    assert result.successful and node.params.z_d == 1.5
    assert node.params.kp == (30.0, 290.0, 1100.0)  # refused changes left it as it was


def test_the_gait_manager_lists_every_block_field_and_refuses_a_bad_value(ros_context):
    node = GaitManagerNode(context=ros_context)
    try:
        names = set(leaf_fields(GaitManagerParameters))
        assert {'posture.stiffness', 'yaw.amplitude', 'enabled'} <= names
        assert all(node.has_parameter(name) for name in names)
        (result,) = node.set_parameters([Parameter('yaw.amplitude', value=-1.0)])
        assert not result.successful and 'yaw.amplitude' in result.reason
        (result,) = node.set_parameters([Parameter('enabled', value=['posture', 'yaw'])])
        assert result.successful and node.params.enabled == {'posture', 'yaw'}
        (result,) = node.set_parameters([Parameter('enabled', value=['posture', 'gait'])])
        assert not result.successful and 'enabled entries must be one of' in result.reason
    finally:
        node.destroy_node()
