"""``coupling_analysis <bag> [--joint 11] [--compare <other bag>] --out DIR [--animate]``: the
eq. (11) analysis of recorded runs (``report.run_analysis``). Exit status
(``iceskate_sim.exit_codes``) 0; 2 with a one-line message for a bag or argument it refuses; 1
with one line when the output cannot be written; 130, 143 or 129 with one line on SIGINT,
SIGTERM or SIGHUP, within about a second, the output folder then as it was (every file is
renamed into it once all are complete). The notes of the
reading go to stderr, and the progress bars when stderr is a terminal (none into a pipe or file).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from iceskate_sim.errors import InputRefused, RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.shutdown import StopRequest, say


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='coupling_analysis',
        description='Eq. (11) coupling analysis of a recorded run, the paper Figs. 5-8, '
                    'CSV of every series, summary.json, optionally a stick-figure animation.')
    parser.add_argument('bag', type=pathlib.Path,
                        help='rosbag2 directory (or a run directory holding bag/)')
    parser.add_argument('--joint', default='11',
                        help='joint of eq. (11): 0-17 or q1..q17 (default 11, right shoulder; '
                             '14 is the left)')
    parser.add_argument('--compare', type=pathlib.Path,
                        help='a second bag (e.g. skate vs skate_no_yaw): adds Figs. 5-8')
    parser.add_argument('--out', type=pathlib.Path, required=True, help='output directory')
    parser.add_argument('--animate', action='store_true',
                        help='also write a stick-figure GIF and a key-frame strip per bag')
    parser.add_argument('--frames', type=int, default=120, help='most GIF frames (default 120)')
    parser.add_argument('--quiet', action='store_true',
                        help='no progress bars (none either when stderr is not a terminal)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Console entry point."""
    with StopRequest() as stop:  # first of all: a signal never ends it half-written
        return _main(argv, stop)


def _main(argv: list[str] | None, stop: StopRequest) -> int:
    args = _parser().parse_args(argv)
    try:
        from iceskate_analysis.report import run_analysis
        if args.frames < 1:
            raise InputRefused(f'--frames must be >= 1, got {args.frames}')
        summary = run_analysis(args.bag, args.out, joint=args.joint, compare=args.compare,
                               animate=args.animate, frames=args.frames,
                               progress=not args.quiet, stop=stop)
    except RunInterrupted as exc:
        say(f'coupling_analysis: {exc}; nothing written into {args.out}')
        return exc.exit_code
    except SimulationError as exc:
        return error_exit('coupling_analysis', exc)
    except OSError as exc:  # the output folder cannot be made or written
        where = f' {exc.filename}' if exc.filename else ''
        return error_exit('coupling_analysis', exc, f'cannot write{where}: {exc.strerror or exc}')
    joint = summary['joint']
    for label, case in summary['cases'].items():
        for note in case.get('notes', []):  # e.g. a bag rebuilt after a killed run
            print(f'coupling_analysis: {label}: note: {note}', file=sys.stderr)
        arms = case['arms']
        print(f'{label}: {case["samples"]} samples, steps {case["steps"]}, closure residual '
              f'max rel {_fmt(case["closure_residual_max_rel"])}; {joint}: RMS h '
              f'{_fmt(case["rms"]["coriolis"])}, RMS(M_total - g) '
              f'{_fmt(case["rms_m_total_minus_g"])} N m; arms p-p q11 '
              f'{_fmt(arms["q11"]["peak_to_peak_deg"])} deg, q14 '
              f'{_fmt(arms["q14"]["peak_to_peak_deg"])} deg, phase '
              f'{_fmt(arms["phase_difference_deg"])} deg')
    print(f'written to {args.out} (summary.json)')
    return DONE


def _fmt(value: float | None) -> str:
    return 'n/a' if value is None else f'{value:.3g}'


if __name__ == '__main__':
    sys.exit(main())
