"""The robot model: coordinates, links and masses (``robot``), the 20 modes of Table 2 (``modes``),
the model terms of eq. (7) (``dynamics``), what controllers see and send (``observation``,
``command``), the moving stance (``stance``), times at a stamp's resolution (``stamps``).
"""
