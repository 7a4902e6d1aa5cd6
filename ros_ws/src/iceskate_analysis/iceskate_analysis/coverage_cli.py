"""``mode_coverage RUN_DIR [RUN_DIR ...] --out DIR``: the modes and transitions finished runs
visited (``iceskate_analysis.coverage``), as ``coverage.md``, ``coverage.json`` and the diagram
``coverage.png``, all three or none (SIGINT, SIGTERM or SIGHUP: exit 128 + the signal's number,
one line).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import signal
import sys
from typing import TYPE_CHECKING

from iceskate_analysis.outputs import StagedFiles
from iceskate_sim.errors import RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.shutdown import StopRequest, raise_if_stopped, say

if TYPE_CHECKING:
    from iceskate_analysis.coverage import Coverage

__all__ = ['main', 'write_coverage']


def write_coverage(coverage: Coverage, out: pathlib.Path, stop: StopRequest | None = None
                   ) -> list[pathlib.Path]:
    """Write ``coverage.md``, ``coverage.json`` and ``coverage.png`` into ``out``, all three or
    none (``StagedFiles``).

    :param stop: looked for before the picture and before the renaming.
    :raises RunInterrupted: on a stop signal (nothing is then written).
    """
    from iceskate_analysis.plots import plot_mode_coverage
    out.mkdir(parents=True, exist_ok=True)
    with StagedFiles(out) as staged:
        staged('coverage.md').write_text(coverage.table(), encoding='utf-8')
        staged('coverage.json').write_text(json.dumps(coverage.as_dict(), indent=1) + '\n',
                                           encoding='utf-8')
        raise_if_stopped(stop)
        plot_mode_coverage(coverage, staged('coverage.png'))
        raise_if_stopped(stop)
        return staged.commit()


def main(argv: list[str] | None = None) -> int:
    """Console entry point ``mode_coverage RUN_DIR ... --out DIR``: exit 0 (one line: the modes
    entered and the files), 2 (a run refused) or 1 (the files not written) with one line on
    stderr saying why, or 128 + the number of a stop signal with one line
    (``iceskate_sim.exit_codes``)."""
    with StopRequest() as stop:  # before the imports of the model (about 0.3 s)
        return _main(argv, stop)


def _main(argv: list[str] | None, stop: StopRequest) -> int:
    parser = argparse.ArgumentParser(
        prog='mode_coverage', description="Which of Table 2's modes and transitions finished "
        "runs visited: a table and a picture laid out like the paper's gait diagram.")
    parser.add_argument('runs', nargs='+', type=pathlib.Path, help='output folders of runs')
    parser.add_argument('--out', type=pathlib.Path, required=True,
                        help='folder for coverage.md, coverage.json and coverage.png')
    args = parser.parse_args(argv)
    from iceskate_analysis.coverage import coverage_of
    from iceskate_sim.model.modes import TABLE_2
    try:
        coverage = coverage_of(args.runs, stop)
        files = write_coverage(coverage, args.out, stop)
    except RunInterrupted as exc:
        say(f'mode_coverage: interrupted by {signal.Signals(exc.signum).name}; nothing written '
            f'into {args.out}')
        return exc.exit_code
    except SimulationError as exc:
        return error_exit('mode_coverage', exc)
    except OSError as exc:
        return error_exit('mode_coverage', exc,
                          f'cannot write into {args.out}: {exc.strerror or exc}')
    missing = f'; never: {", ".join(map(str, coverage.missing))}' if coverage.missing else ''
    print(f'{len(coverage.visited)} of {len(TABLE_2)} modes entered{missing}; '
          f'{", ".join(str(f) for f in files)}', flush=True)
    return DONE


if __name__ == '__main__':
    sys.exit(main())
