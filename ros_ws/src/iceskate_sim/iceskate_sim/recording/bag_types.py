"""Register the iceskate_interfaces message types in a rosbags typestore (ROS-free).

The bag writer (recorder) and the offline analysis read and write rosbag2 bags with ``rosbags``
and need our custom message definitions. They come from the ``.msg`` files of the
``iceskate_interfaces`` package, so no ROS build and no ``rclpy`` import are needed.

Lookup order of the ``.msg`` directory:

1. ``<prefix>/share/iceskate_interfaces/msg`` for every ``<prefix>`` in ``$AMENT_PREFIX_PATH``
   (what an installed workspace provides; no ``ament_index`` import),
2. the source tree: ``ros_ws/src/interfaces/msg`` next to this package's source.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ['INTERFACES_PACKAGE', 'OFFERED_QOS', 'PASSIVE', 'find_msg_dir', 'make_typestore',
           'msg_types']

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

# ros_ws/src/iceskate_sim/iceskate_sim/recording/bag_types.py -> ros_ws/src/interfaces/msg
# (resolve() follows colcon's --symlink-install links back to the source tree).
_SOURCE_MSG_DIR = Path(__file__).resolve().parents[3] / 'interfaces' / 'msg'


def _candidate_dirs() -> list[Path]:
    """Return the directories searched for ``*.msg`` files, in lookup order."""
    candidates = []
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            candidates.append(Path(prefix) / 'share' / INTERFACES_PACKAGE / 'msg')
    candidates.append(_SOURCE_MSG_DIR)
    return candidates


def find_msg_dir() -> Path:
    """Return the first directory that holds the ``iceskate_interfaces`` ``.msg`` files.

    :return: directory containing at least one ``*.msg`` file.
    :raises FileNotFoundError: when no candidate directory holds ``.msg`` files; the message
        lists every directory searched.
    """
    candidates = _candidate_dirs()
    for directory in candidates:
        if directory.is_dir() and any(directory.glob('*.msg')):
            return directory
    searched = ', '.join(str(c) for c in candidates)
    raise FileNotFoundError(f'no {INTERFACES_PACKAGE} .msg files found; searched: {searched}')


def msg_types(msg_dir: Path | str | None = None) -> dict:
    """Parse every ``.msg`` file of ``iceskate_interfaces`` into rosbags type definitions.

    :param msg_dir: directory of the ``.msg`` files; default: :func:`find_msg_dir`.
    :return: mapping ``'iceskate_interfaces/msg/<Name>'`` to its rosbags definition, ready for
        ``Typestore.register``.
    :raises FileNotFoundError: when ``msg_dir`` holds no ``.msg`` file.
    """
    directory = Path(msg_dir) if msg_dir is not None else find_msg_dir()
    paths = sorted(directory.glob('*.msg'))
    if not paths:
        raise FileNotFoundError(f'no .msg files in {directory}')
    types: dict = {}
    for path in paths:
        name = f'{INTERFACES_PACKAGE}/msg/{path.stem}'
        types.update(get_types_from_msg(path.read_text(encoding='utf-8'), name))
    return types


def make_typestore(msg_dir: Path | str | None = None) -> Typestore:
    """Return a ROS 2 Jazzy typestore with the ``iceskate_interfaces`` messages registered.

    :param msg_dir: directory of the ``.msg`` files; default: :func:`find_msg_dir`.
    :return: a new ``Typestore`` (``Stores.ROS2_JAZZY`` plus our types).
    :raises FileNotFoundError: when the ``.msg`` files cannot be found.
    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    typestore.register(msg_types(msg_dir))
    return typestore
