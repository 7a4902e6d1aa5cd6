"""Offline analysis of recorded runs (no ROS, no re-simulation).

* ``bag_io``: read a rosbag2 bag into time-aligned arrays (``read_bag``).
* ``coupling``: the paper's eq. (11) at a joint (default the right shoulder q11), the arm swing
  (peak-to-peak, correlation, phase) and the per-case summary.
* ``plots``: the paper's Figs. 5-8 as PNG.
* ``animation``: a stick-figure GIF and a key-frame strip of a run.

The console script ``coupling_analysis`` (``iceskate_analysis.coupling_cli``) drives them.
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
