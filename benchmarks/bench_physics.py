#!/usr/bin/env python3
"""Physics alone, side by side with MuJoCo: one 1 ms control period against ``mj_step``.

Everything is measured in one run, so the ratios hold for one machine and one hour:

* **MuJoCo** (the PyPI ``mujoco`` wheel, a benchmark-only dependency) on our own URDF,
  ``iceskate_humanoid.urdf``, loaded as it is: the pelvis is the root link, which MuJoCo's URDF
  import welds to the world (pelvis fixed); the URDF has no geometry, and contacts are disabled
  on top; no actuator, no controller; the URDF's joint damping and limits carry over. Timestep
  1 ms. Microseconds per ``mj_step`` with the ``implicitfast`` and the ``RK4`` integrator, from
  the joint angles and speeds of the states below (our support-rooted coordinates mapped to the
  URDF joints with ``anatomical_map``), ``--number`` steps per timing run from each state.
* **Our simulator** at the shipped settings of the ``skate`` scene (implicit Euler, 1 ms
  step, 1 ms control period, so a period is one step): the scene runs for ``--warmup`` s with
  its controllers, then ``--states`` states are taken one every
  ``--spacing`` periods, each with the command the controllers held over its period. From each
  state whose period fires no event: (a) ``NativeProbes.integrate_segment`` to the period
  end (the native segment call: one implicit-Euler step, three eq. (7) solves (start, implicit
  step, end), the guards at both ends) and the kernel's own binding call; (b) the whole
  control period: the kernel's ``HybridSimulator.advance`` (the period in C++: the start
  evaluation, settle, the segment, the end-of-period projection, the health checks; the
  binding call alone) and ``Simulator.advance`` (that call plus the Python that mirrors the
  state, events and counters); one eq. (7) solve (``NativeProbes.evaluate`` and the
  kernel's ``evaluate``).

Before each timed ``advance`` the simulator is put back to the state (``Simulator.set_state``:
the kernel continues from it as after a period that ended there; the dynamics' kept state terms
as the previous period leaves them: a solve at this state under the previous command); the
advance from every state is checked to reproduce the recorded run. The timings take turns, so
that a change of the machine's load during the run weighs on all of them alike: from each state
MuJoCo's two integrators, then the native calls; the two advances alternate, state by state.
Figures are microseconds per call: per state the median over ``--repeat`` timings (after one to
warm up), then the median over the states (with their range). The ratios are ours /
``mj_step`` implicitfast; the goal compared with is physics alone <= 1.5x MuJoCo's ``mj_step`` at
the same step.

Usage (from the repository root, environment sourced):
    python benchmarks/bench_physics.py [--states 20] [--repeat 25] [--number 200] [--json PATH]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import json
import pathlib
import statistics
import sys
import time
import timeit
from typing import Any

from bench_work_precision import machine_info
import numpy as np

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene
from iceskate_sim.model.command import HeldCommand
from iceskate_sim.model.robot import N_COORDINATES, anatomical_map, load_robot
from iceskate_sim.physics.hybrid import HybridState
from iceskate_sim.physics.simulation import Simulator

# the native kernel's single calls are test tools (tests/oracle)
sys.path.append(str(pathlib.Path(__file__).resolve().parents[1] / 'tests'))
from oracle.commands import held_of_controllers, stack_commands
from oracle.native_probes import NativeProbes  # noqa: E402

GOAL_RATIO = 1.5  # physics alone <= 1.5 x mj_step (implicitfast) at the same step


@dataclass
class Snapshot:
    """A simulator state at the end of a period, and what the next period holds."""

    state: HybridState
    previous: HeldCommand  # the command held over the period that ended here
    command: HeldCommand  # the command the controllers give for the next period
    after: HybridState | None = None  # the state the run reached one period later
    quiet: bool = False  # no transition in the next period, one integration step


def restore(sim: Simulator, snap: Snapshot) -> None:
    """Put ``sim`` back where the run was at ``snap``, its dynamics' kept state terms as the
    previous period leaves them (its last solve at this state, under the previous command)."""
    sim.set_state(snap.state)
    NativeProbes.of(sim.dynamics).evaluate(snap.state.contact, snap.state.q, snap.state.v,
                                           snap.previous.bias, None, snap.previous.stiffness,
                                           snap.previous.damping)


def collect_states(scene, robot, warmup: float, count: int, spacing: int) -> list[Snapshot]:
    """Run the scene with its controllers and keep ``count`` states after ``warmup`` s."""
    sim = Simulator(robot, scene.simulator, scene.initial)
    stack = ControlStack(scene, robot, sim.observation())
    period = scene.simulator.control_period
    first = int(round(warmup / period))
    snaps: list[Snapshot] = []
    previous = HeldCommand.torque_only(np.zeros(N_COORDINATES))
    for k in range(first + count * spacing):
        command = held_of_controllers(stack_commands(stack, sim.observation()).values())
        snap = None
        if k >= first and (k - first) % spacing == 0:
            snap = Snapshot(sim.state, previous, command)
            steps, events, rests = sim.stats.steps, len(sim.events), sim.stats.suppressed_cycles
        sim.advance(command)
        previous = command
        if sim.ended is not None:
            raise SystemExit(f'the skate run ended at t={sim.time:.3f} s ({sim.ended})')
        if snap is not None:
            snap.after = sim.state
            snap.quiet = (sim.stats.steps - steps == 1 and len(sim.events) == events
                          and sim.stats.suppressed_cycles == rests)
            snaps.append(snap)
    return snaps


def per_state(values: list[float]) -> dict[str, float]:
    """Median over the states of their medians, and the range."""
    return {'median': statistics.median(values), 'min': min(values), 'max': max(values)}


def time_calls(func, repeat: int, number: int) -> float:
    """Median over ``repeat`` runs of the mean time of ``number`` calls [us]."""
    func()
    runs = timeit.Timer(func).repeat(repeat=repeat, number=number)
    return statistics.median(runs) / number * 1e6


def kernel_advance(sim: Simulator) -> Any:
    """The native period's binding call alone (``HybridSimulator.advance``) of ``sim``'s
    kernel; ``sim`` mirrors nothing of it (its next ``set_state`` does)."""
    kernel = sim.kernel

    def advance(command: HeldCommand) -> None:
        kernel.advance(command.bias, command.stiffness, command.damping, '', None)
    return advance


def time_advance(advances: list[tuple[Simulator, Any]], snaps: list[Snapshot], repeat: int
                 ) -> tuple[list[list[float]], list[float]]:
    """Median wall time [us] of each ``(simulator, advance)`` call from each state (the calls in
    turn from each state, the states in turn in each repeat, so no state is kept from one repeat
    to the next), and for each the largest difference of its end state from the run."""
    clock = time.perf_counter
    timings = [[[] for _ in snaps] for _ in advances]
    deviation = [0.0 for _ in advances]
    for _ in range(repeat + 1):  # the first round warms up
        for i, snap in enumerate(snaps):
            for k, (sim, advance) in enumerate(advances):
                restore(sim, snap)
                t0 = clock()
                advance(snap.command)
                timings[k][i].append((clock() - t0) * 1e6)
                state = sim.kernel.state  # the kernel's: the kernel call mirrors nothing
                t, q, v = state['t'], state['q'], state['v']
                deviation[k] = max(deviation[k], abs(t - snap.after.t),
                                   float(np.max(np.abs(q - snap.after.q))),
                                   float(np.max(np.abs(v - snap.after.v))))
    return [[statistics.median(t[1:]) for t in per_sim] for per_sim in timings], deviation


def mujoco_model(urdf: pathlib.Path, robot) -> tuple[Any, Any, dict[str, Any]]:
    """MuJoCo's model of our URDF (1 ms, contacts off) and what it holds."""
    import mujoco
    model = mujoco.MjModel.from_xml_path(str(urdf))
    model.opt.timestep = 1.0e-3
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    urdf_model = robot.urdf_model
    damping_equal = all(
        model.dof_damping[model.jnt_dofadr[j]]
        == urdf_model.damping[urdf_model.joints[urdf_model.getJointId(name)].idx_v]
        for j, name in enumerate(names))
    bodies = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(model.nbody)]
    info = {
        'mujoco': mujoco.__version__, 'nq': int(model.nq), 'nv': int(model.nv),
        'nbody': int(model.nbody), 'bodies': bodies, 'njnt': int(model.njnt),
        'hinges': int(np.sum(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)),
        'limited': int(np.sum(model.jnt_limited)), 'ngeom': int(model.ngeom),
        'nu': int(model.nu), 'moving_mass': float(np.sum(model.body_mass)),
        'total_mass': float(robot.total_mass), 'damping_as_urdf': bool(damping_equal),
        'damping': {name: float(model.dof_damping[model.jnt_dofadr[j]])
                    for j, name in enumerate(names)},
    }
    return mujoco, model, info


def mujoco_states(mujoco, model, snaps: list[Snapshot]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Our states' joint angles and speeds as MuJoCo's qpos, qvel (same joints, pelvis fixed)."""
    states = []
    for snap in snaps:
        qpos, qvel = np.zeros(model.nq), np.zeros(model.nv)
        for i, joint, sign in anatomical_map(snap.state.contact.side):
            j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
            qpos[model.jnt_qposadr[j]] = sign * snap.state.q[i]
            qvel[model.jnt_dofadr[j]] = sign * snap.state.v[i]
        states.append((qpos, qvel))
    return states


def time_mj_step(mujoco, model, data, state: tuple[np.ndarray, np.ndarray], integrator: str,
                 repeat: int, number: int) -> tuple[float, float]:
    """Median us per ``mj_step`` from ``state`` (``number`` steps a timing run, the state set
    anew before each), and the mean count of active constraints (joint limits) at the runs'
    ends."""
    model.opt.integrator = int(getattr(mujoco.mjtIntegrator, integrator))
    step = mujoco.mj_step
    clock = time.perf_counter
    runs, nefc = [], []
    for _ in range(repeat + 1):  # the first run warms up
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = state
        mujoco.mj_forward(model, data)
        t0 = clock()
        for _ in range(number):
            step(model, data)
        runs.append((clock() - t0) / number * 1e6)
        nefc.append(int(data.nefc))
    return statistics.median(runs[1:]), statistics.fmean(nefc[1:])


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, optionally write JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--warmup', type=float, default=1.0,
                        help='simulated time [s] of skate before the first state')
    parser.add_argument('--states', type=int, default=20, help='states taken from the run')
    parser.add_argument('--spacing', type=int, default=10, help='periods between two states')
    parser.add_argument('--repeat', type=int, default=25, help='timings per state (median)')
    parser.add_argument('--number', type=int, default=200,
                        help='calls per timing of a short call (segment, evaluate, mj_step)')
    parser.add_argument('--json', type=pathlib.Path, metavar='PATH',
                        help='also write the figures to this JSON file')
    args = parser.parse_args(argv)
    started = time.perf_counter()
    info = machine_info()

    robot = load_robot()
    scene = load_scene('skate')
    config = scene.simulator
    snaps = collect_states(scene, robot, args.warmup, args.states, args.spacing)
    quiet = [s for s in snaps if s.quiet]
    if not quiet:
        raise SystemExit('every state fires an event in its period: change --warmup/--spacing')
    rep, num = args.repeat, args.number

    # MuJoCo on the same joint states
    mujoco, model, mj = mujoco_model(robot.urdf_path, robot)
    data = mujoco.MjData(model)
    states = mujoco_states(mujoco, model, quiet)

    # per state, in turn: mj_step (both integrators), (a) the native segment call and the
    # kernel's binding call, one eq. (7) solve
    native_sim = Simulator(robot, config, scene.initial)
    native = NativeProbes.of(native_sim.dynamics)
    mj_implicitfast, mj_rk4, nefc_implicitfast, nefc_rk4 = [], [], [], []
    segment, kernel_segment, evaluate, kernel_evaluate = [], [], [], []
    for snap, state in zip(quiet, states, strict=True):
        us, nefc = time_mj_step(mujoco, model, data, state, 'mjINT_IMPLICITFAST', rep, num)
        mj_implicitfast.append(us)
        nefc_implicitfast.append(nefc)
        us, nefc = time_mj_step(mujoco, model, data, state, 'mjINT_RK4', rep, num)
        mj_rk4.append(us)
        nefc_rk4.append(nefc)
        s, c = snap.state, snap.command
        end = s.t + config.control_period
        seg = native.integrate_segment(s, c, None, config.integrator, config.friction, {}, end)
        if seg.fired is not None or seg.steps != 1:
            raise SystemExit(f'an event fires in the segment from t={s.t:.4f} s')
        segment.append(time_calls(
            lambda s=s, c=c, e=end: native.integrate_segment(
                s, c, None, config.integrator, config.friction, {}, e), rep, num))
        (mode, side, pivot, anchor, support_dir, heel_dir, q, v, tau, stiffness, damping,
         frame, force) = evaluate_args = native._arguments(s.contact, s.q, s.v, c.bias, None,
                                                           c.stiffness, c.damping)
        segment_args = (mode, side, pivot, anchor, support_dir, heel_dir, tau, stiffness,
                        damping, frame, force, config.integrator.method,
                        config.integrator.step, config.integrator.rtol,
                        config.integrator.atol, config.integrator.event_tolerance,
                        *native._guard_arguments(mode, s.t, {}, config.friction),
                        s.t, np.concatenate([s.q, s.v]), end)
        kernel_segment.append(time_calls(
            lambda a=segment_args: native.kernel.integrate_segment(*a), rep, num))
        evaluate.append(time_calls(
            lambda s=s, c=c: native.evaluate(s.contact, s.q, s.v, c.bias, None, c.stiffness,
                                             c.damping), rep, num))
        kernel_evaluate.append(time_calls(
            lambda a=evaluate_args: native.kernel.evaluate(*a), rep, num))
    nefc_implicitfast = statistics.fmean(nefc_implicitfast)
    nefc_rk4 = statistics.fmean(nefc_rk4)

    # (b) the whole period: the kernel call and Simulator.advance, in turn from each state
    kernel_sim = Simulator(robot, config, scene.initial)
    (advance_kernel, advance_native), deviations = time_advance(
        [(kernel_sim, kernel_advance(kernel_sim)), (native_sim, native_sim.advance)], quiet,
        rep)
    deviation_kernel, deviation_native = deviations

    rows = {
        'mj_step implicitfast': per_state(mj_implicitfast),
        'mj_step RK4': per_state(mj_rk4),
        '(a) NativeProbes.integrate_segment': per_state(segment),
        '    kernel integrate_segment (binding call)': per_state(kernel_segment),
        '(b) kernel HybridSimulator.advance': per_state(advance_kernel),
        '(b) Simulator.advance': per_state(advance_native),
        'eq. (7): NativeProbes.evaluate': per_state(evaluate),
        'eq. (7): kernel evaluate (binding call)': per_state(kernel_evaluate),
    }
    base = rows['mj_step implicitfast']['median']
    elapsed = time.perf_counter() - started

    print('iceskate physics against MuJoCo, measured in one run')
    print(f'machine: {info["cpu"]}, {info["cpus"]} CPUs, {info["platform"]}; load average at '
          f'start {info["loadavg_start"]}; {info["date"]}')
    print(f'Python {info["python"]}, numpy {info["numpy"]}, pinocchio {info["pinocchio"]}, '
          f'mujoco {mj["mujoco"]}')
    print()
    print(f'MuJoCo model of {robot.urdf_path.name}: nq {mj["nq"]}, nv {mj["nv"]}, '
          f'{mj["nbody"]} bodies (world + {mj["nbody"] - 1} moving links; the pelvis, the '
          'root link, welded to the world), '
          f'{mj["hinges"]} hinges ({mj["limited"]} with limits), {mj["ngeom"]} geoms, '
          f'{mj["nu"]} actuators; moving mass {mj["moving_mass"]:.1f} of '
          f'{mj["total_mass"]:.1f} kg; joint damping as in the URDF: '
          f'{"yes" if mj["damping_as_urdf"] else "NO"}; timestep 1 ms, contacts disabled; '
          f'active constraints (joint limits) per step, mean: implicitfast '
          f'{nefc_implicitfast:.2f}, RK4 {nefc_rk4:.2f}')
    print(f'ours: skate scene, {config.integrator.method}, step '
          f'{config.integrator.step * 1e3:g} ms, control period '
          f'{config.control_period * 1e3:g} ms, projection '
          f'{config.integrator.projection}; states every '
          f'{args.spacing} periods from t = {args.warmup:g} s: {len(quiet)} of {len(snaps)} '
          f'fire no event in their period (modes '
          f'{sorted({s.state.mode.number for s in quiet})}); the advance from them reproduces '
          f'the run to {deviation_kernel:.1e} (kernel call), {deviation_native:.1e} '
          '(Simulator.advance)')
    print(f'timings: per state the median of {rep} runs (short calls: {num} calls per run, '
          f'advance: one period per run), then the median over the {len(quiet)} states')
    print()
    print(f'{"per 1 ms period (one step)":<44} {"median us":>10} {"range over states":>19} '
          f'{"/ mj_step implicitfast":>23}')
    for name, row in rows.items():
        spread = f'{row["min"]:.1f}-{row["max"]:.1f}'
        print(f'{name:<44} {row["median"]:10.1f} {spread:>19} '
              f'{row["median"] / base:22.2f}x')
    print()
    a = rows['(a) NativeProbes.integrate_segment']['median'] / base
    b_kernel = rows['(b) kernel HybridSimulator.advance']['median'] / base
    b = rows['(b) Simulator.advance']['median'] / base
    verdict = {True: 'meets', False: 'misses'}
    print(f'ratios ours / mj_step implicitfast: (a) native segment {a:.1f}x, (b) native period '
          f'{b_kernel:.1f}x (kernel call), {b:.1f}x (Simulator.advance); goal <= '
          f'{GOAL_RATIO:g}x: the native period {verdict[b_kernel <= GOAL_RATIO]}')
    python_part = (rows['(b) Simulator.advance']['median']
                   - rows['(b) kernel HybridSimulator.advance']['median'])
    print(f'Simulator.advance - kernel advance, the Python mirror of a native period: '
          f'{python_part:.1f} us; benchmark wall time {elapsed:.0f} s')

    if args.json:
        figures = {
            'machine': info, 'mujoco_model': mj, 'scene': 'skate',
            'integrator': config.integrator.method, 'step': config.integrator.step,
            'control_period': config.control_period, 'warmup': args.warmup,
            'spacing': args.spacing, 'states': len(snaps), 'quiet_states': len(quiet),
            'repeat': rep, 'number': num, 'nefc_mean': {'implicitfast': nefc_implicitfast,
                                                        'rk4': nefc_rk4},
            'deviation': {'kernel': deviation_kernel, 'simulator': deviation_native},
            'us': {name.strip(): row for name, row in rows.items()},
            'ratio_to_mj_step_implicitfast': {name.strip(): row['median'] / base
                                              for name, row in rows.items()},
            'goal_ratio': GOAL_RATIO, 'wall_s': elapsed,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2) + '\n')
        print(f'figures written to {args.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
