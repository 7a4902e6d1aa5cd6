"""ros2 launch iceskate_sim iceskate.launch.py scene:=stand [out_dir:=DIR record_bag:=DIR/bag]

The three nodes of the graph (what ``run_scene <scene> --ros`` starts without ROS 2 launch);
the whole launch shuts down when the simulator exits at the end of the run. A controller whose
law the scene does not run stays idle. Real-time scheduling, as ``run_scene --rt-priority 10``:
``ros2 launch --launch-prefix 'chrt --fifo 10' iceskate_sim iceskate.launch.py scene:=skate``.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def _config(package: str, node: str) -> PathJoinSubstitution:
    return PathJoinSubstitution([FindPackageShare(package), 'config', f'{node}.yaml'])


def generate_launch_description() -> LaunchDescription:
    """The simulator, visual_lifting and gait_manager nodes for one scene."""
    scene = ParameterValue(LaunchConfiguration('scene'), value_type=str)
    simulator = Node(
        package='iceskate_sim', executable='simulator', name='simulator', output='screen',
        parameters=[_config('iceskate_sim', 'simulator'), {
            'scene': scene,
            'out_dir': ParameterValue(LaunchConfiguration('out_dir'), value_type=str),
            'record_bag': ParameterValue(LaunchConfiguration('record_bag'), value_type=str)}])
    controllers = [
        Node(package=package, executable=package, name=package, output='screen',
             parameters=[_config(package, package), {'scene': scene}])
        for package in ('visual_lifting', 'gait_manager')]
    return LaunchDescription([
        DeclareLaunchArgument('scene', default_value='stand',
                              description='shipped scene name or scene YAML path'),
        DeclareLaunchArgument('out_dir', default_value='',
                              description='directory for metrics.json (empty: none)'),
        DeclareLaunchArgument('record_bag', default_value='',
                              description='MCAP bag path to record (empty: none)'),
        simulator, *controllers,
        RegisterEventHandler(OnProcessExit(target_action=simulator, on_exit=[
            EmitEvent(event=Shutdown(reason='the simulator finished the run'))])),
    ])
