"""The visual-lifting parameters (docs/model.md §10): ``VisualLiftingParameters``, from which the
C++ struct the law reads is generated at build time. See docs/architecture.md, 'One parameter
schema'.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from iceskate_native.parameters import checked, from_mapping, setting
from visual_lifting.errors import VisualLiftingError

#: The forward targets y_d: 'moving' y_H(0) + v_d t, 'follow' y_H(t), 'fixed' y_H(0).
DESIRED_Y_OPTIONS = ('moving', 'follow', 'fixed')


@dataclass(frozen=True)
class VisualLiftingParameters:
    """Parameters of the visual-lifting law (docs/model.md, visual lifting); the node declares
    them as typed ROS parameters (``ros2 param list /visual_lifting``)."""

    kp: tuple[float, float, float] = setting(
        (20.0, 290.0, 1100.0), 'K_p = diag(k_y, k_z, k_pitch) on the head pose (y, z, pitch); '
        'the paper: 20, 290, 1100', unit='N/m, N/m, N m/rad', low=0.0)
    joints: tuple[int, ...] = setting(
        (1, 2, 3, 4, 8, 9, 10, 17), 'joints that receive the torque (support foot to head); a '
        'joint gets torque only while its coordinate is active in the mode', low=1, high=17,
        distinct=True)
    joint1_torque: bool = setting(True, 'apply the joint-1 (floor pivot) entry while q1 is active')
    desired_y: str = setting(
        'moving', "forward target y_d: 'moving' y_H(0) + v_d t, 'follow' y_H(t) (forward term "
        "off), 'fixed' y_H(0)", choices=DESIRED_Y_OPTIONS)
    v_d: float = setting(0.3, "forward speed of the 'moving' target", unit='m/s', low=-5.0,
                         high=5.0)
    z_d: float | None = setting(None, 'target head-top height; unset (NaN): the initial height',
                                unit='m', low=0.0, open_low=True)
    pitch_d: float = setting(0.0, 'target head pitch', unit='rad', low=-1.0, high=1.0)
    max_dy: float | None = setting(0.3, 'saturation of |y_d - y|; unset (NaN): none', unit='m',
                                   low=0.0, open_low=True)
    shift_y1: float = setting(0.0, 'forward shift of the target after a support exchange (the '
                              "gait manager's moving stance)", unit='m', low=-0.4, high=0.4)
    shift_z1: float = setting(0.0, 'downward shift of the target after a support exchange',
                              unit='m', low=-0.1, high=0.3)
    shift_time1: float = setting(0.6, 'duration of the first shift', unit='s', low=0.0)
    shift_y2: float = setting(0.0, 'further forward shift after the swing heel strike', unit='m',
                              low=-0.4, high=0.4)
    shift_time2: float = setting(0.5, 'duration of the second shift', unit='s', low=0.0)
    __post_init__ = checked(VisualLiftingError)  # errors name the key

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> VisualLiftingParameters:
        """Build from a mapping (e.g. YAML); unknown keys and bad values raise an error."""
        return from_mapping(cls, d, VisualLiftingError)

