"""Which of Table 2's 20 modes and which transitions finished runs visited (the empirical
gait-transition diagram), from their ``events.json``: a table (``coverage.md``, and
``coverage.json``) and a picture laid out like the paper's diagram (``coverage.png``: the
support-foot states as rows, the swing-foot states as columns, each visited transition an arrow
with its count). Only the modes the dynamics entered count: a run's initial mode, a set-up
state, is not a visit.
``mode_coverage RUN_DIR [RUN_DIR ...] --out DIR`` (``coverage_cli``) writes them for a set of
runs.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
import json
import pathlib
from typing import TYPE_CHECKING, Any

from iceskate_sim.errors import InputRefused
from iceskate_sim.files import regular_file
from iceskate_sim.model.modes import SUPPORT_STATES, SWING_STATES, TABLE_2
from iceskate_sim.physics.hybrid import CAUSES, RESOLVED

if TYPE_CHECKING:
    from iceskate_sim.shutdown import StopRequest

__all__ = ['KIND_OF_EVENT', 'Coverage', 'coverage_of', 'load_events']

#: The kind of each transition guard (docs/model.md §6): the support foot rolling onto or off
#: an edge, sticking or starting to glide, the support exchange, the swing foot's impacts
#: (heel, sole, toe first), its heel sticking or sliding, its sole un-flattening, its release;
#: 'R' ends a cycle of single switches in the contact-consistent mode.
KIND_OF_EVENT = {
    'E1': 'support roll', 'E2': 'support roll', 'E3': 'support roll',
    'E4': 'support stick/slip', 'E5': 'support stick/slip', 'E6': 'exchange',
    'S1': 'impact', 'S4': 'impact', 'S7': 'impact (toe first)',
    'S2': 'swing stick/slip', 'S3': 'swing stick/slip', 'S5': 'swing roll', 'S6': 'release',
    'R': 'switch cycle resolved',
}
_CAUSE = CAUSES | {'R': RESOLVED}


@dataclass
class Coverage:
    """What a set of runs visited.

    :ivar runs: the runs' names, in order.
    :ivar entries: mode -> times the dynamics entered it (over all runs).
    :ivar time_s: mode -> simulated time spent in it [s] (its initial stretch included).
    :ivar visited_by: mode -> the runs that entered it.
    :ivar transitions: (from mode, to mode, event) -> count.
    """

    runs: list[str] = field(default_factory=list)
    entries: Counter[int] = field(default_factory=Counter)
    time_s: Counter[int] = field(default_factory=Counter)
    visited_by: dict[int, list[str]] = field(default_factory=dict)
    transitions: Counter[tuple[int, int, str]] = field(default_factory=Counter)

    @property
    def visited(self) -> list[int]:
        """The modes the dynamics entered, in Table 2's order."""
        return sorted(mode for mode in TABLE_2 if self.entries[mode])

    @property
    def missing(self) -> list[int]:
        """The modes no run entered."""
        return [mode for mode in TABLE_2 if not self.entries[mode]]

    def add(self, name: str, events: Sequence[Mapping[str, Any]], duration: float,
            still: int | None = None) -> None:
        """Count the transitions of run ``name`` (``events`` in time order, ``duration`` [s]
        simulated; ``still``: the mode of a run without transitions, its whole duration).

        :raises InputRefused: on an event that names no mode of Table 2 or no guard.
        """
        self.runs.append(name)
        for k, event in enumerate(events):
            mode, to, guard = event['from_mode'], event['to_mode'], event['event']
            if mode not in TABLE_2 or to not in TABLE_2 or guard not in KIND_OF_EVENT:
                raise InputRefused(f'{name}: event {k} ({guard}: {mode} -> {to}) is not a '
                                   'transition between modes of Table 2')
            self.time_s[mode] += float(event['t']) - (float(events[k - 1]['t']) if k else 0.0)
            self.transitions[(mode, to, guard)] += 1
            if to == mode:  # a resolved switch cycle that changed only the side or pivot
                continue
            self.entries[to] += 1
            if name not in self.visited_by.setdefault(to, []):
                self.visited_by[to].append(name)
        if events:
            self.time_s[events[-1]['to_mode']] += duration - float(events[-1]['t'])
        elif still in TABLE_2:
            self.time_s[still] += duration

    def as_dict(self) -> dict[str, Any]:
        """The coverage as JSON-ready data (``coverage.json``)."""
        return {
            'runs': self.runs, 'visited': self.visited, 'missing': self.missing,
            'modes': {str(mode): {'support': support, 'swing': swing,
                                  'entries': self.entries[mode],
                                  'time_s': self.time_s[mode],
                                  'runs': self.visited_by.get(mode, [])}
                      for mode, (support, swing) in TABLE_2.items()},
            'transitions': [{'from_mode': a, 'to_mode': b, 'event': e, 'kind': KIND_OF_EVENT[e],
                             'count': n} for (a, b, e), n in sorted(self.transitions.items())],
        }

    def table(self) -> str:
        """The coverage as Markdown (``coverage.md``): the modes, then the transitions."""
        lines = [f'# Modes and transitions of {len(self.runs)} run(s): {", ".join(self.runs)}',
                 '', f'{len(self.visited)} of {len(TABLE_2)} modes of Table 2 entered; '
                 + (f'never: {", ".join(map(str, self.missing))}.' if self.missing
                    else 'every one.'), '',
                 '| mode | support foot | swing foot | entries | time [s] | runs |',
                 '| ---: | --- | --- | ---: | ---: | --- |']
        for mode, (support, swing) in TABLE_2.items():
            lines.append(f'| {mode} | {support} ({SUPPORT_STATES[support][2]}) | {swing} '
                         f'({SWING_STATES[swing][2]}) | {self.entries[mode]} | '
                         f'{self.time_s[mode]:.3f} | {", ".join(self.visited_by.get(mode, []))} |')
        lines += ['', '| from | to | event | kind | count |', '| ---: | ---: | --- | --- | ---: |']
        lines += [f'| {a} | {b} | {e} ({_CAUSE.get(e, "")}) | {KIND_OF_EVENT[e]} | {n} |'
                  for (a, b, e), n in sorted(self.transitions.items())]
        return '\n'.join(lines) + '\n'


def load_events(run_dir: pathlib.Path) -> tuple[list[dict[str, Any]], float, int | None]:
    """(events, simulated duration [s], the mode of a run that stayed in one) of a finished
    run's ``events.json`` and ``metrics.json``.

    :raises InputRefused: naming the file that is missing or not what a run writes.
    """
    loaded = []
    for path in (run_dir / 'events.json', run_dir / 'metrics.json'):
        if path.exists():  # a FIFO would block the read
            regular_file(path, 'run file')
        try:
            loaded.append(json.loads(path.read_text(encoding='utf-8')))
        except OSError as exc:
            raise InputRefused(f'{run_dir} is not a finished run: {exc.strerror or exc} '
                               f'({path})') from None
        except ValueError as exc:
            raise InputRefused(f'{path} is not JSON ({exc})') from None
    events, metrics = loaded

    def transition(e: Any) -> bool:
        return (isinstance(e, dict) and isinstance(e.get('t'), (int, float))
                and all(isinstance(e.get(f), int) for f in ('from_mode', 'to_mode'))
                and isinstance(e.get('event'), str))
    if not isinstance(events, list) or not all(map(transition, events)):
        raise InputRefused(f'{run_dir / "events.json"}: not an event log (a list of '
                           'transitions, each with a time t [s], integer from_mode and '
                           'to_mode, and an event name)')
    duration = metrics.get('sim_time_s') if isinstance(metrics, dict) else None
    if not isinstance(duration, (int, float)):
        raise InputRefused(f'{run_dir / "metrics.json"}: no sim_time_s (the run did not '
                           'start)')
    modes = metrics.get('mode_time_fraction')
    still = next(iter(modes)) if isinstance(modes, dict) and len(modes) == 1 else None
    return events, float(duration), int(still) if str(still).isdigit() else None


def coverage_of(run_dirs: Iterable[pathlib.Path], stop: StopRequest | None = None
                ) -> Coverage:
    """The coverage of the finished runs in ``run_dirs`` (``stop`` looked for before each).

    :raises InputRefused: naming a run that cannot be read.
    :raises RunInterrupted: on a stop signal.
    """
    coverage = Coverage()
    for run_dir in run_dirs:
        if stop is not None and stop.requested:
            raise stop.error(None)
        coverage.add(run_dir.name, *load_events(run_dir))
    return coverage
