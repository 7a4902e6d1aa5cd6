"""Register the iceskate_interfaces message types in a rosbags typestore (ROS-free):
``make_typestore``, from the ``.msg`` files the package installs (found through the ament index).
See docs/usage.md, 'Through ROS 2: the node graph, bags, replay, analysis'.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from iceskate_sim.installed import share_path

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ['INTERFACES_PACKAGE', 'OFFERED_QOS', 'PASSIVE', 'make_typestore', 'msg_types']

#: ROS package that defines our messages.
INTERFACES_PACKAGE = 'iceskate_interfaces'
#: Source name of the joint damping and soft-stop torques in JointDynamics.source_names.
PASSIVE = 'passive'
#: The QoS a topic is offered with where it differs from a plain reliable one, in rosbag2's
#: metadata form: the URDF is latched (reliable, transient local, depth 1). The simulator node
#: publishes it so and the bag says so, so that ``ros2 bag play`` and Foxglove hand it to late
#: subscribers. Durations 0: the middleware's defaults.
OFFERED_QOS = {'/robot_description': [{
    'history': 'keep_last', 'depth': 1, 'reliability': 'reliable',
    'durability': 'transient_local', 'deadline': {'sec': 0, 'nsec': 0},
    'lifespan': {'sec': 0, 'nsec': 0}, 'liveliness': 'automatic',
    'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
    'avoid_ros_namespace_conventions': False}]}


def msg_types(msg_dir: Path | str | None = None) -> dict:
    """Parse every ``.msg`` file of ``iceskate_interfaces`` into rosbags type definitions.

    :param msg_dir: directory of the ``.msg`` files; default: the one the package installs.
    :return: mapping ``'iceskate_interfaces/msg/<Name>'`` to its rosbags definition, ready for
        ``Typestore.register``.
    :raises SimulationError: if the package is not installed.
    :raises FileNotFoundError: when ``msg_dir`` holds no ``.msg`` file.
    """
    directory = Path(msg_dir) if msg_dir is not None else share_path(INTERFACES_PACKAGE, 'msg')
    paths = sorted(directory.glob('*.msg'))
    if not paths:
        raise FileNotFoundError(f'no .msg files in {directory}')
    types: dict = {}
    for path in paths:
        name = f'{INTERFACES_PACKAGE}/msg/{path.stem}'
        types.update(get_types_from_msg(path.read_text(encoding='utf-8'), name))
    return types


def make_typestore() -> Typestore:
    """Return a new ROS 2 Jazzy typestore with the installed ``iceskate_interfaces`` messages
    registered.

    :raises SimulationError: when ``iceskate_interfaces`` is not installed.
    :raises FileNotFoundError: when its ``.msg`` folder holds no ``.msg`` file.
    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    typestore.register(msg_types())
    return typestore
