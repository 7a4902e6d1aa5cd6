#!/usr/bin/env python3
"""Speed of eq. (7): one evaluation per Table 2 mode, the Python test oracle and the native core.

For every mode (grouped by coordinate count 16/17/18) it times one evaluation of the Python
eq. (7) the native core is tested against (``GaitDynamics.evaluate``, the test oracle
``tests/oracle/dynamics.py``) at a representative random state (bent stance plus noise, seeded;
a new state every call, so the state terms ``evaluate`` keeps are never reused), the same state
evaluated again ("kept": what a period's second and third evaluations cost), the free-flyer
cross-check ``FloatingBaseDynamics.evaluate`` (``tests/oracle/floating_base.py``) at the same
state, and the individual Pinocchio calls and the linear solve that ``evaluate`` is made of;
and the native core at the same states: ``NativeProbes.evaluate`` (the C++ kernel behind
the same Python interface) and the
kernel's own binding call (``kernel``: argument checks, eq. (7), the result's arrays), with the
ratio Python / native measured in this run. Figures are the median over ``--repeat`` runs
of ``--number`` calls each, in microseconds per call. The 18-coordinate modes are compared with
the 60 us target.

Usage (from the repository root):
    python benchmarks/bench_dynamics.py [--repeat 15] [--number 200] [--json out.json]
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import json
import pathlib
import platform
import statistics
import sys
import timeit

import numpy as np

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
TARGET_US = 60.0  # per evaluation, 18-coordinate modes
SEED = 20190605


def _import_core():
    """Import iceskate_sim, from the source tree when the workspace is not sourced."""
    if importlib.util.find_spec('iceskate_sim') is None:
        sys.path.insert(0, str(REPO_ROOT / 'ros_ws' / 'src' / 'iceskate_sim'))
    import pinocchio as pin

    # eq. (7) in Python and the free-flyer cross-check are test oracles (tests/oracle), imported
    # as the tests do
    if str(REPO_ROOT / 'tests') not in sys.path:
        sys.path.append(str(REPO_ROOT / 'tests'))
    from iceskate_sim.model.dynamics import ContactState, DynamicsParameters
    from iceskate_sim.model.modes import MODES
    from iceskate_sim.model.robot import JOINT_LIMITS, load_robot
    from oracle.dynamics import GaitDynamics
    from oracle.floating_base import FloatingBaseDynamics
    return (pin, ContactState, DynamicsParameters, GaitDynamics, FloatingBaseDynamics, MODES,
            JOINT_LIMITS, load_robot)


def _time_us(func, repeat: int, number: int) -> float:
    """Median over ``repeat`` runs of the mean time of ``number`` calls, in microseconds."""
    func()  # warm up (first-call allocations, caches)
    runs = timeit.Timer(func).repeat(repeat=repeat, number=number)
    return statistics.median(runs) / number * 1e6


def _state(mode, rng, joint_limits):
    """Bent stance + U(-0.3, 0.3), inside the stops; velocities U(-1, 1) on active coords."""
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    q[2:] += rng.uniform(-0.3, 0.3, 16)
    for i, (lower, upper) in joint_limits.items():
        q[i] = np.clip(q[i], lower + 0.05, upper - 0.05)
    q[0] = rng.uniform(-1.0, 1.0)
    q[1] = rng.uniform(-0.2, 0.0) if mode.q1_active else 0.0
    v = np.zeros(18)
    v[mode.active] = rng.uniform(-1.0, 1.0, mode.n_coordinates)
    tau = rng.uniform(-20.0, 20.0, 18)
    return q, v, tau


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, optionally write JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=15, help='timing runs (median taken)')
    parser.add_argument('--number', type=int, default=200, help='calls per timing run')
    parser.add_argument('--side', default='right', choices=('right', 'left'))
    parser.add_argument('--pivot', default='toe', choices=('toe', 'heel'))
    parser.add_argument('--json', type=pathlib.Path, metavar='PATH',
                        help='also write the figures to this JSON file')
    args = parser.parse_args(argv)
    (pin, ContactState, DynamicsParameters, GaitDynamics, FloatingBaseDynamics, MODES,
     JOINT_LIMITS, load_robot) = _import_core()
    from oracle.dynamics import _solve  # the linear solve of evaluate
    from oracle.native_probes import NativeProbes

    robot = load_robot()
    params = DynamicsParameters(mu=0.005)
    dynamics = GaitDynamics(robot, params)
    native = NativeProbes(robot, params)
    floating = FloatingBaseDynamics(robot, params)
    sm = robot.support_model(args.side, args.pivot)
    model = sm.model
    data = model.createData()
    heel = sm.frame_ids['swing_heel']
    lwa = pin.LOCAL_WORLD_ALIGNED
    rng = np.random.default_rng(SEED)
    rep, num = args.repeat, args.number

    rows = []
    for number in sorted(MODES):
        mode = MODES[number]
        contact = ContactState(mode, args.side, args.pivot)
        q, v, tau = _state(mode, rng, JOINT_LIMITS)
        # three states in turn: every call misses the two states evaluate keeps
        states = itertools.cycle([(q, v, tau)] + [_state(mode, rng, JOINT_LIMITS)
                                                  for _ in range(2)])
        result = dynamics.evaluate(contact, q, v, tau)
        applied = result.applied
        kernel_arguments = native._arguments(contact, q, v, tau, None, None, None)
        size = mode.n_coordinates + len(mode.constraints)
        A = np.eye(size) + 0.01 * rng.standard_normal((size, size))
        b = rng.standard_normal(size)
        rows.append({
            'mode': number,
            'support': mode.support,
            'swing': mode.swing,
            'n': mode.n_coordinates,
            'n_c': len(mode.constraints),
            'evaluate_us': _time_us(lambda c=contact, s=states:
                                    dynamics.evaluate(c, *next(s)), rep, num),
            'kept_us': _time_us(lambda c=contact, q=q, v=v, t=tau:
                                dynamics.evaluate(c, q, v, t), rep, num),
            'floating_base_us': _time_us(lambda c=contact, q=q, v=v, a=applied:
                                         floating.evaluate(c, q, v, a), rep, num),
            'solve_us': _time_us(lambda A=A, b=b: _solve(A, b), rep, num),
            'native_us': _time_us(lambda c=contact, s=states:
                                  native.evaluate(c, *next(s)), rep, num),
            'kernel_us': _time_us(lambda a=kernel_arguments:
                                  native.kernel.evaluate(*a), rep, num),
        })

    # The Pinocchio calls evaluate() makes (same 18-joint model in every mode).
    q, v, tau = _state(MODES[20], rng, JOINT_LIMITS)
    zeros = np.zeros(18)
    qdd = dynamics.evaluate(ContactState(MODES[20], args.side, args.pivot), q, v, tau).qdd
    pin.computeAllTerms(model, data, q, v)
    pin.forwardKinematics(model, data, q, v, zeros)
    calls = {
        'computeAllTerms': lambda: pin.computeAllTerms(model, data, q, v),
        'forwardKinematics(q, v, 0) (ref.)': lambda: pin.forwardKinematics(model, data, q, v,
                                                                          zeros),
        'getFrameJacobian (LWA)': lambda: pin.getFrameJacobian(model, data, heel, lwa),
        'getFrameClassicalAcceleration': lambda: pin.getFrameClassicalAcceleration(
            model, data, heel, lwa),
        'updateFramePlacement': lambda: pin.updateFramePlacement(model, data, heel),
        'centerOfMass (acceleration)': lambda: pin.centerOfMass(
            model, data, pin.KinematicLevel.ACCELERATION, False),
        'rnea (support wrench)': lambda: pin.rnea(model, data, q, v, qdd),
        'crba (reference)': lambda: pin.crba(model, data, q),
        'aba (reference, unconstrained)': lambda: pin.aba(model, data, q, v, tau),
    }
    pinocchio_us = {name: _time_us(func, rep, num) for name, func in calls.items()}

    print(f'iceskate dynamics benchmark: Python {platform.python_version()}, pinocchio '
          f'{pin.__version__}, numpy {np.__version__}, {platform.machine()}; support '
          f'{args.side}/{args.pivot}; median of {rep} x {num} calls')
    print()
    header = (f'{"mode":>4} {"support":>7} {"swing":>5} {"n":>3} {"n_c":>3} '
              f'{"evaluate us":>12} {"kept us":>8} {"floating us":>12} {"solve us":>9} '
              f'{"eval/60us":>9} {"native us":>10} {"kernel us":>10} {"py/native":>9}')
    groups = {}
    for row in rows:
        groups.setdefault(row['n'], []).append(row)
    for n in sorted(groups):
        print(f'--- {n} coordinates ---')
        print(header)
        for row in groups[n]:
            ratio = f'{row["evaluate_us"] / TARGET_US:9.2f}' if n == 18 else f'{"":>9}'
            print(f'{row["mode"]:>4} {row["support"]:>7} {row["swing"]:>5} {row["n"]:>3} '
                  f'{row["n_c"]:>3} {row["evaluate_us"]:12.1f} {row["kept_us"]:8.1f} '
                  f'{row["floating_base_us"]:12.1f} '
                  f'{row["solve_us"]:9.1f} {ratio} {row["native_us"]:10.1f} '
                  f'{row["kernel_us"]:10.1f} {row["evaluate_us"] / row["native_us"]:9.2f}')
        median = statistics.median(r['evaluate_us'] for r in groups[n])
        native_median = statistics.median(r['native_us'] for r in groups[n])
        kernel_median = statistics.median(r['kernel_us'] for r in groups[n])
        print(f'     median over the {len(groups[n])} modes: evaluate {median:.1f} us, native '
              f'{native_median:.1f} us (kernel call {kernel_median:.1f} us): Python / native '
              f'= {median / native_median:.2f}')
        print()
    print('Pinocchio calls (one call each, us):')
    for name, us in pinocchio_us.items():
        print(f'  {name:<34} {us:8.2f}')
    worst18 = max(r['evaluate_us'] for r in groups.get(18, []))
    print()
    print(f'18-coordinate modes: worst evaluate {worst18:.1f} us = '
          f'{worst18 / TARGET_US:.2f} x the {TARGET_US:.0f} us target')

    if args.json:
        figures = {
            'python': platform.python_version(),
            'pinocchio': pin.__version__,
            'numpy': np.__version__,
            'machine': platform.machine(),
            'side': args.side,
            'pivot': args.pivot,
            'repeat': rep,
            'number': num,
            'target_us': TARGET_US,
            'modes': rows,
            'pinocchio_us': pinocchio_us,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2) + '\n')
        print(f'figures written to {args.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
