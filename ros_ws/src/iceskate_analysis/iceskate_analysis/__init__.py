"""Offline analysis of recorded runs (no re-simulation): ``bag_io`` reads a bag,
``coupling`` evaluates the paper's eq. (11) and the arm swing, ``plots``, ``animation`` and
``summary`` draw; the console scripts are ``coupling_analysis`` and ``replay``.
"""

from iceskate_analysis.bag_io import BagData, read_bag
from iceskate_analysis.coupling import (
    ArmSwing,
    CaseResult,
    JointDecomposition,
    analyse_case,
    arm_swing,
    decompose,
)

__all__ = ['ArmSwing', 'BagData', 'CaseResult', 'JointDecomposition', 'analyse_case',
           'arm_swing', 'decompose', 'read_bag']
