"""Controllers written in Python for tests/iceskate_bringup/test_plugin.py (imported as the
module ``plugin_controllers``, its folder put on sys.path by the tests)."""

from __future__ import annotations

import numpy as np

import iceskate_native


class FailsAt(iceskate_native.Controller):
    """Zero torque until ``t_fail`` [s], then what ``how`` says: 'nan' (a NaN entry), 'short'
    (17 entries), 'raise' (a ZeroDivisionError), 'source' (an unknown source)."""

    def __init__(self, how: str = 'nan', t_fail: float = 0.0) -> None:
        super().__init__()
        self.how, self.t_fail = how, t_fail

    def compute(self, obs: iceskate_native.Observation,
                kinematics: iceskate_native.Kinematics) -> object:
        """The failure from t_fail on."""
        tau = np.zeros(18)
        if obs.t < self.t_fail:
            return tau
        if self.how == 'nan':
            tau[3] = np.nan
            return tau
        if self.how == 'short':
            return tau[:17]
        if self.how == 'source':
            return {'sources': {'elsewhere': tau}}
        return 1.0 / 0.0  # 'raise'


class TwoSources(iceskate_native.Controller):
    """A torque source 'push_knee' and an impedance source 'hold_ankle' with a head target."""

    sources = ('push_knee', 'hold_ankle')

    def compute(self, obs: iceskate_native.Observation,
                kinematics: iceskate_native.Kinematics) -> object:
        """Constant commands."""
        tau = np.zeros(18)
        tau[4] = 2.0
        k, d, ref = np.zeros(18), np.zeros(18), np.zeros(18)
        k[3], d[3], ref[3] = 10.0, 1.0, 0.1
        return {'sources': {'push_knee': tau,
                            'hold_ankle': {'effort': np.zeros(18), 'stiffness': k, 'damping': d,
                                           'reference': ref}},
                'head_target': [0.0, 1.5, 0.0]}


class PlainLaw:
    """No Controller subclass: a plain object with compute (wrapped by PluginAdapter)."""

    def __init__(self, gain: float = 1.0) -> None:
        self.gain = gain

    def compute(self, obs: iceskate_native.Observation,
                kinematics: iceskate_native.Kinematics) -> list[float]:
        """-gain * v, as a list."""
        return list(-self.gain * obs.v)


class NamedSources(iceskate_native.Controller):
    """No torque, under the source names it is given (``names``)."""

    def __init__(self, names: tuple[str, ...] = ('posture',)) -> None:
        super().__init__()
        self.sources = tuple(names)

    def compute(self, obs: iceskate_native.Observation,
                kinematics: iceskate_native.Kinematics) -> object:
        """Zero torque from each source."""
        return {'sources': {name: np.zeros(18) for name in self.sources}}
