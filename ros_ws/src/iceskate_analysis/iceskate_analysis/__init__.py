"""Offline analysis of recorded runs (no re-simulation): ``bag_io`` reads a bag,
``coupling`` evaluates the paper's eq. (11) and the arm swing, ``plots``, ``animation`` and
``summary`` draw; the console scripts are ``coupling_analysis`` and ``replay``.
"""
