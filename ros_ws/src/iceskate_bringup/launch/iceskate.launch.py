"""ros2 launch iceskate_bringup iceskate.launch.py scene:=stand out_dir:=DIR

The nodes of the graph for one scene (what ``run_scene <scene> --ros --out DIR`` starts without
ROS 2 launch): the scene is composed into one parameter file per node in DIR/params/
(``iceskate_bringup.graph.graph_nodes``), then the simulator and the controller nodes the scene
runs start with them; the whole launch shuts down when the simulator exits at the end of the
run. Real-time scheduling, as ``run_scene --rt-priority 10``:
``ros2 launch --launch-prefix 'chrt --fifo 10' iceskate_bringup iceskate.launch.py scene:=skate``.
"""

import pathlib
import tempfile

from launch import LaunchContext, LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from iceskate_bringup.graph import graph_nodes


def _nodes(context: LaunchContext) -> list:
    """The nodes of the scene, with the parameter files composed from it."""
    out = LaunchConfiguration('out_dir').perform(context) or tempfile.mkdtemp(prefix='iceskate-')
    specs = graph_nodes(LaunchConfiguration('scene').perform(context), pathlib.Path(out))
    nodes = [Node(package=s.package, executable=s.executable, name=s.node,
                  output='screen', arguments=s.ros_args()) for s in specs]
    return [*nodes, RegisterEventHandler(OnProcessExit(target_action=nodes[0], on_exit=[
        EmitEvent(event=Shutdown(reason='the simulator finished the run'))]))]


def generate_launch_description() -> LaunchDescription:
    """The simulator and the controller nodes of one scene."""
    return LaunchDescription([
        DeclareLaunchArgument('scene', default_value='stand',
                              description='shipped scene name or scene YAML path'),
        DeclareLaunchArgument('out_dir', default_value='',
                              description='directory for the outputs, the bag and params/ '
                                          '(empty: a new temporary directory)'),
        OpaqueFunction(function=_nodes),
    ])
