"""``EffortCommand`` as CDR bytes, both ways, without message objects (the lockstep's hot path):
``CommandDecoder`` (the simulator) and ``CommandEncoder`` (the controller nodes).
See docs/performance.md, 'End to end: recording, start-up, the whole command, the graph'.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from rosbags.typesys.store import Typestore

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues, all_finite
from iceskate_sim.model.robot import COORDINATE_NAMES
from iceskate_sim.model.stamps import NS_PER_S
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.cdr import Layout, LayoutError, layout_for, layout_of
from iceskate_sim.ros.conversions import command_from_message

#: The float64 sequences of an EffortCommand, in order.
ARRAYS = ('effort', 'stiffness', 'damping', 'position_reference', 'source_efforts',
          'head_target')
_TYPE = 'iceskate_interfaces/msg/EffortCommand'
_STAMP = ('header.stamp.sec', 'header.stamp.nanosec')


class ForeignCommand(SimulationError):
    """A command that does not carry the run's token: another node on the domain answers the
    run's states (``source``: the controller it names)."""

    #: How such commands are counted in metrics.json (one reason, whatever names they carry).
    REASON = 'a command not of this run (its run token differs)'

    def __init__(self, source: str) -> None:
        super().__init__(f'a command naming {source[:64]!r} is not of this run (its run token '
                         "differs): another node on this ROS domain answers the run's states")
        self.source = source[:64]


def _stamp_ns(layout: Layout, data: bytes) -> int:
    sec, nanosec = (int(layout.read(data, path)[0]) for path in _STAMP)
    return sec * NS_PER_S + nanosec


class CommandDecoder:
    """``effort_commands`` CDR bytes -> (source, stamp [ns], command), every message checked
    as ``command_from_message`` checks it (see the module docstring); ``run_token``: the token
    every command of this run carries ('' for nodes started by hand); ``typestore``: the types
    (default: ``make_typestore()``)."""

    def __init__(self, run_token: str = '', typestore: Typestore | None = None) -> None:
        self.run_token = run_token
        self._typestore = typestore or make_typestore()
        #: per source: its last checked message's layout, the places of its values and sources
        self._known: dict[str, tuple[Layout, np.ndarray, tuple[slice, ...], tuple[str, ...]]] = {}

    def decode(self, data: bytes) -> tuple[str, int, CommandValues]:
        """The sender, stamp and command values of one message (views of ``data`` when its
        layout is known).

        :raises SimulationError: naming the problem (and the source, once it is readable);
            a command of another run (``ForeignCommand``).
        """
        data = bytes(data)
        for source, (layout, every, arrays, sources) in self._known.items():
            if layout.fits(data):  # the skeleton holds the source's name and the run's token
                values = self._values(data, layout, every, arrays, sources)
                if values is not None:
                    return source, _stamp_ns(layout, data), values
                break
        try:
            layout = layout_of(self._typestore, _TYPE, data)
        except LayoutError as exc:
            raise SimulationError(f'undecodable effort_commands message ({len(data)} bytes): '
                                  f'{exc}') from None
        if layout.strings['run_token'] != self.run_token:
            raise ForeignCommand(layout.strings['source'])
        message = SimpleNamespace(
            stamp_ns=_stamp_ns(layout, data), frame_id=layout.strings['header.frame_id'],
            source=layout.strings['source'], joint_names=layout.texts('joint_names'),
            source_names=layout.texts('source_names'),
            **{name: layout.read(data, name).copy() for name in ARRAYS})
        values = command_from_message(message)
        if message.joint_names == list(COORDINATE_NAMES):  # the layout the fast way assumes
            first = layout.fields[ARRAYS[0]].offset  # each array's doubles from there on
            arrays = tuple(slice((f.offset - first) // 8, (f.offset - first) // 8 + f.count)
                           for f in (layout.fields[name] for name in ARRAYS))
            every = np.concatenate([np.arange(a.start, a.stop) for a in arrays])
            self._known[message.source] = (layout, every, arrays, tuple(message.source_names))
        return message.source, message.stamp_ns, values

    @staticmethod
    def _values(data: bytes, layout: Layout, every: np.ndarray, arrays: tuple[slice, ...],
                sources: tuple[str, ...]) -> CommandValues | None:
        """The values in ``data`` (all 18 names in order, as checked before); None when a
        value is not finite or a gain negative (the checked way then says which)."""
        first = layout.fields[ARRAYS[0]].offset  # the arrays are 8-aligned from here on
        doubles = np.frombuffer(data, '<f8', (layout.size - first) // 8, first)
        values = doubles[every]
        gains = np.concatenate([doubles[arrays[1]], doubles[arrays[2]]])
        if not all_finite(values) or (gains.size and min(gains.tolist()) < 0.0):
            return None
        return CommandValues(*(doubles[array] for array in arrays), sources)


class CommandEncoder:
    """A controller's ``CommandValues`` -> its ``effort_commands`` CDR bytes (see the module
    docstring); ``source``: the controller's name; ``run_token``: its run's token ('': none);
    ``typestore``: the types (default: ``make_typestore()``)."""

    def __init__(self, source: str, run_token: str = '',
                 typestore: Typestore | None = None) -> None:
        self.source, self.run_token = source, run_token
        self._typestore = typestore or make_typestore()
        self._last: tuple[tuple, iceskate_native.CdrProgram] | None = None
        self._stamp = np.zeros((1, 1), dtype=np.int64)

    def encode(self, values: CommandValues, stamp_ns: int) -> bytes:
        """The message of the command ``values`` to the state stamped ``stamp_ns`` [ns] >= 0."""
        arrays = values[:6]
        shape = (values.sources, *(x.size for x in arrays))
        if self._last is None or self._last[0] != shape:
            layout = layout_for(self._typestore, _TYPE, {
                'source': self.source, 'run_token': self.run_token,
                'joint_names': COORDINATE_NAMES,
                'source_names': values.sources,
                **{name: x.size for name, x in zip(ARRAYS, arrays, strict=True)}})
            # column 0: the stamp [ns]; column 1 + k: array k of ARRAYS
            self._last = (shape, layout.program({
                'header.stamp': [(0, 0)],
                **{name: [(1 + k, i) for i in range(x.size)]
                   for k, (name, x) in enumerate(zip(ARRAYS, arrays, strict=True))}}))
        if stamp_ns < 0:
            raise SimulationError(f'a stamp needs a time >= 0, got {stamp_ns} ns')
        self._stamp[0, 0] = stamp_ns
        return iceskate_native.encode_rows(
            self._last[1], [self._stamp, *(x.reshape(1, -1) for x in arrays)], 1)[0].tobytes()
