"""DDS on this machine only: the environment that keeps a process's Fast DDS on loopback
(docs/usage.md, "DDS stays on loopback")."""

from __future__ import annotations

from collections.abc import MutableMapping

from iceskate_sim.errors import SimulationError
from iceskate_sim.installed import share_path

#: Where Fast DDS reads a participant profile from (2.x and 3.x names).
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')


def loopback_dds(env: MutableMapping[str, str]) -> None:
    """Keep the DDS of the processes started with ``env`` (``os.environ``: this one) on this
    machine. Unless a Fast DDS profile of the user's is named, the project's
    (``share/iceskate_sim/config/fastdds_loopback.xml``: every socket on 127.0.0.1, discovery
    by unicast to 127.0.0.1) with the discovery range SUBNET, under which rmw
    applies the profile as it is (the range LOCALHOST confines where discovery sends, but then
    rmw_fastrtps opens sockets on every interface); with a profile of the user's, or without
    ours (not installed), the range LOCALHOST."""
    try:
        ours = share_path('iceskate_sim', 'config', 'fastdds_loopback.xml')
    except SimulationError:
        ours = None
    named = {env[v] for v in PROFILE_VARIABLES if env.get(v)}
    if ours is not None and ours.is_file() and named <= {str(ours)}:
        env.update(dict.fromkeys(PROFILE_VARIABLES, str(ours)))
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'SUBNET'
    else:
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.pop('ROS_LOCALHOST_ONLY', None)
