"""``mode_coverage RUN_DIR [RUN_DIR ...] --out DIR``: the modes and transitions finished runs
visited (``iceskate_analysis.coverage``), as ``coverage.md``, ``coverage.json`` and the diagram
``coverage.png``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

from iceskate_analysis.coverage import Coverage, coverage_of
from iceskate_analysis.plots import plot_mode_coverage
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.modes import TABLE_2
from iceskate_sim.shutdown import say

__all__ = ['main', 'write_coverage']


def write_coverage(coverage: Coverage, out: pathlib.Path) -> list[pathlib.Path]:
    """Write ``coverage.md``, ``coverage.json`` and ``coverage.png`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / 'coverage.md').write_text(coverage.table(), encoding='utf-8')
    (out / 'coverage.json').write_text(json.dumps(coverage.as_dict(), indent=1) + '\n',
                                       encoding='utf-8')
    return [out / 'coverage.md', out / 'coverage.json',
            plot_mode_coverage(coverage, out / 'coverage.png')]


def main(argv: list[str] | None = None) -> int:
    """Console entry point ``mode_coverage RUN_DIR ... --out DIR``: exit 0 (one line: the modes
    entered and the files), or 1 with one line on stderr saying why."""
    parser = argparse.ArgumentParser(
        prog='mode_coverage', description="Which of Table 2's modes and transitions finished "
        "runs visited: a table and a picture laid out like the paper's gait diagram.")
    parser.add_argument('runs', nargs='+', type=pathlib.Path, help='output folders of runs')
    parser.add_argument('--out', type=pathlib.Path, required=True,
                        help='folder for coverage.md, coverage.json and coverage.png')
    args = parser.parse_args(argv)
    try:
        coverage = coverage_of(args.runs)
        files = write_coverage(coverage, args.out)
    except SimulationError as exc:
        say(f'mode_coverage: error: {exc}')
        return 1
    except OSError as exc:
        say(f'mode_coverage: error: cannot write into {args.out}: {exc.strerror or exc}')
        return 1
    missing = f'; never: {", ".join(map(str, coverage.missing))}' if coverage.missing else ''
    print(f'{len(coverage.visited)} of {len(TABLE_2)} modes entered{missing}; '
          f'{", ".join(str(f) for f in files)}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
