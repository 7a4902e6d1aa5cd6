#!/usr/bin/env python3
"""Speed of the ROS 2 lockstep graph at a 1 ms control period (a benchmark, not a test).

For each scene it runs ``--duration`` simulated seconds (0: the whole scene; bag recorded, as
``run_scene``, unless ``--no-bag``) three ways and prints the real-time factor (simulated / wall
time of the control loop):

* headless: ``iceskate_bringup.runner.run`` (physics + laws, no transport), the lower bound;
* graph, 3 processes: simulator, visual_lifting, gait_manager as separate processes;
* graph, 1 process: the three nodes on one EventsExecutor;
* with ``--rt-priority N`` also: graph, 3 processes under real-time scheduling (SCHED_FIFO at
  priority N; its runs alternate with the default ones, so both see the same hour).

From the simulator's loop timings (``stats_file``) it prints, per control period, the median,
p95 and p99 of the round trip (state published -> last command in) and the median and p99 of
the physics step. The per-hop latency is estimated as (round trip - slowest controller's
compute) / 2, with the controllers' compute timed in this process on the scene's initial
observation.

It also measures the messaging floor of the three-process lockstep: the same messages per
period (/clock and gait_state out to two processes with use_sim_time; one EffortCommand with
the scene's breakdown back from each) with no physics and no control law
(``--floor-periods``; 0 skips it). The real-time factor cannot exceed control period / (floor +
the compute on the critical path).

Usage (from the repository root, after ``make setup`` and ``. ./env.sh``):
    python benchmarks/bench_graph.py [--duration 0.5] [--scenes skate tests/...yaml] [--json F]
    python benchmarks/bench_graph.py --scenes skate --duration 0 --repeat 3 --floor-periods 0
        (the speed goal where it is stated: the whole skate scene, three runs of the graph;
        add --no-bag for the lockstep alone, without the bag writer, and --rt-priority 10
        for the same graph under SCHED_FIFO beside it)
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
import pathlib
import statistics
import struct
import sys
import tempfile
import time
import timeit

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
GOAL_RTF = 4.0  # the three-process graph's real-time factor, whole skate scene with bag
DEFAULT_SCENES = ['skate', str(REPO_ROOT / 'tests' / 'integration' / 'data' / 'tiny_stand.yaml')]


def controller_compute_ms(scene) -> dict[str, float]:
    """Median time [ms] of each controller node's law (the native one the nodes call, with the
    command values they send) at the scene's initial observation."""
    from iceskate_bringup.composition import ControlStack
    from iceskate_sim.model.robot import load_robot
    from iceskate_sim.physics.native_control import native_observation, native_values
    from iceskate_sim.physics.simulation import Simulator
    robot = load_robot()
    obs = Simulator(robot, scene.simulator, scene.initial).observation()
    stack = ControlStack(scene, robot, obs)
    native = native_observation(obs)
    return {node: _median_ms(lambda c=controller: native_values(c, native, stack.kinematics))
            for node, controller in stack.controllers.items()}


def _median_ms(func) -> float:
    func()
    return statistics.median(timeit.Timer(func).repeat(repeat=7, number=50)) / 50 * 1e3


def bench_scene(scene_arg: str, duration: float, work: pathlib.Path, repeat: int = 1,
                bag: bool = True, rt_priority: int = 0) -> dict:
    """Headless, 3-process (``repeat`` times) and 1-process runs of one scene.

    :param duration: simulated s per run; 0 or less: the scene's own duration.
    :param bag: record the bag (if the scene records one) in every run.
    :param rt_priority: also run the 3-process graph under SCHED_FIFO at this priority
        (``three_process_fifo``, its runs alternating with the default ones; 0: not).
    """
    from iceskate_bringup.graph import run_graph
    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene
    scene = load_scene(scene_arg)
    duration = duration if duration > 0 else scene.duration
    scene = replace(scene, duration=duration, record_bag=scene.record_bag and bag)
    name = scene.name
    result = {'scene': name, 'duration_s': duration, 'bag': scene.record_bag,
              'control_period_s': scene.simulator.control_period,
              'controller_compute_ms': controller_compute_ms(scene), 'rt_priority': rt_priority}
    result['headless_rtf'] = run(scene, work / f'{name}-headless', progress=False)[
        'real_time_factor']
    variants = [('three_process', False, 0, repeat)]
    if rt_priority:
        variants.append(('three_process_fifo', False, rt_priority, repeat))
    variants.append(('single_process', True, 0, 1))
    rtfs: dict[str, list[float]] = {label: [] for label, *_ in variants}
    loops: dict[str, dict] = {}
    for k in range(repeat):  # the variants' runs alternate
        for label, single, priority, runs in variants:
            if k >= runs:
                continue
            out = work / f'{name}-{label}-{k}'
            stats = work / f'{name}-{label}-{k}-stats.json'
            metrics = run_graph(scene_arg, out, duration=duration, single_process=single,
                                stats_file=str(stats), timeout=60.0 + 20.0 * duration,
                                rt_priority=priority,
                                **({} if scene.record_bag else {'record_bag': ''}))
            rtfs[label].append(metrics['real_time_factor'])
            loops[label] = json.loads(stats.read_text())  # the loop timings of the last run
    slowest = max(result['controller_compute_ms'].values(), default=0.0)
    for label, loop in loops.items():
        round_trip = [1e3 * x for x in loop['round_trip']]
        result[label] = {'rtf': statistics.median(rtfs[label]), 'rtf_runs': rtfs[label],
                         'round_trip_ms': round_trip,
                         'physics_ms': [1e3 * x for x in loop['physics']],
                         'periods': loop['periods'],
                         'hop_estimate_ms': max(0.0, (round_trip[0] - slowest) / 2.0)}
    return result


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=DEFAULT_SCENES)
    parser.add_argument('--duration', type=float, default=0.5,
                        help="simulated s per run (0: each scene's own duration)")
    parser.add_argument('--repeat', type=int, default=1,
                        help='runs of the three-process graph (its RTF: their median)')
    parser.add_argument('--bag', action=argparse.BooleanOptionalAction, default=True,
                        help='record the bag in every run (--no-bag: the loop alone)')
    parser.add_argument('--json', type=pathlib.Path, help='also write the figures here')
    parser.add_argument('--floor-periods', type=int, default=3000,
                        help='periods of the messaging-floor loop (0: skip it)')
    parser.add_argument('--rt-priority', type=int, default=0, metavar='N',
                        help='also run the three-process graph under SCHED_FIFO at priority N '
                             '(runs alternating with the default scheduling; needs root, '
                             'CAP_SYS_NICE or an rtprio limit)')
    parser.add_argument('--echo', help=argparse.SUPPRESS)  # internal: one echo process
    args = parser.parse_args(argv)
    if args.echo:
        return _echo(args.echo, args.scenes[0])
    results = []
    with tempfile.TemporaryDirectory(prefix='bench-graph-') as tmp:
        for scene in args.scenes:
            r = bench_scene(scene, args.duration, pathlib.Path(tmp), max(1, args.repeat),
                            args.bag, args.rt_priority)
            results.append(r)
            print(f"\nscene {r['scene']}: {r['duration_s']} s at "
                  f"{1e3 * r['control_period_s']:g} ms, {'with' if r['bag'] else 'no'} bag; "
                  "controller compute "
                  + ', '.join(f'{k} {1e3 * v:.1f} us'
                              for k, v in r['controller_compute_ms'].items()))
            print(f"  headless                 RTF {r['headless_rtf']:.3f}")
            for label in ('three_process', 'three_process_fifo', 'single_process'):
                if label not in r:
                    continue
                g = r[label]
                rt, ph = g['round_trip_ms'], g['physics_ms']
                runs = (f' (median of {len(g["rtf_runs"])} runs: '
                        + ', '.join(f'{x:.3f}' for x in g['rtf_runs']) + ')'
                        if len(g['rtf_runs']) > 1 else '')
                print(f'  graph {label:<18} RTF {g["rtf"]:.3f}{runs}; round trip median/p95/p99 '
                      f'{rt[0]:.2f}/{rt[1]:.2f}/{rt[2]:.2f} ms; physics median/p99 '
                      f'{ph[0]:.2f}/{ph[2]:.2f} ms; hop ~ {g["hop_estimate_ms"]:.2f} ms')
            if r['bag'] and 'three_process' in r and scene == 'skate' and args.duration == 0:
                rtf = r['three_process']['rtf']
                print(f'  three-process graph with bag: RTF {rtf:.2f} (goal >= {GOAL_RTF:g} under '
                      f'the default scheduling on the whole skate scene: '
                      f'{"met" if rtf >= GOAL_RTF else "NOT met"})')
    if args.floor_periods > 0:
        floor = messaging_floor(args.scenes[0], args.floor_periods)
        results.append({'messaging_floor_ms': floor, 'scene': args.scenes[0]})
        print(f'\nmessaging floor (three processes, no physics, no law; scene {args.scenes[0]}): '
              f'{floor:.3f} ms per period -> RTF <= {1.0 / floor:.2f} at a 1 ms period '
              'before any compute')
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + '\n')
    return 0


def messaging_floor(scene_arg: str, periods: int) -> float:
    """Wall time per period [ms] of the lockstep's messages alone (median of 3 blocks).

    This process publishes the scene's t = 0 state (/clock and gait_state, the simulator's CDR
    bytes, published raw as the node does) and waits for one EffortCommand from each of two
    echo processes (``--echo``: use_sim_time, the gait_state subscription, the scene's
    breakdown), like the simulator node; nothing is computed.
    """
    import subprocess

    import rclpy
    from rclpy.experimental import EventsExecutor
    from rosgraph_msgs.msg import Clock

    from iceskate_bringup.graph import ros_environment, stop
    from iceskate_bringup.scene import load_scene, scene_sources
    from iceskate_interfaces.msg import EffortCommand, GaitState
    from iceskate_sim.ros.lockstep import CONTROL_TOPICS, LockstepSession
    from iceskate_sim.ros.node_support import CLOCK_QOS, LOCKSTEP_READER_QOS, STATE_QOS
    from iceskate_sim.run.session import Session
    scene = load_scene(scene_arg)
    session = LockstepSession(Session(scene), scene_sources(scene))
    payloads = list(session.state_bytes(CONTROL_TOPICS).values())
    env = ros_environment()
    echoes = [subprocess.Popen([sys.executable, __file__, '--echo', name, '--scenes', scene_arg],
                               env=env, start_new_session=True)
              for name in session.controllers]
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(env['ROS_DOMAIN_ID']))
    try:
        node = rclpy.create_node('floor', context=context)
        types = {'/clock': (Clock, CLOCK_QOS), '/gait_state': (GaitState, STATE_QOS)}
        publishers = [node.create_publisher(*types[t][:1], t, types[t][1])
                      for t in CONTROL_TOPICS]
        answers = [0]
        node.create_subscription(EffortCommand, 'effort_commands',
                                 lambda _: answers.__setitem__(0, answers[0] + 1),
                                 LOCKSTEP_READER_QOS, raw=True)
        executor = EventsExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 60.0
        n = len(echoes)
        while (publishers[-1].get_subscription_count() < n
               or node.count_publishers('effort_commands') < n):
            if time.monotonic() > deadline:
                raise RuntimeError('the echo processes did not come up within 60 s')
            executor.spin_once(timeout_sec=0.05)
        time.sleep(1.0)  # discovery traffic settles
        blocks = []
        for _ in range(3):
            start = time.perf_counter()
            for _ in range(periods // 3):
                expected = answers[0] + n
                for publisher, payload in zip(publishers, payloads, strict=True):
                    publisher.publish(payload)
                deadline = time.monotonic() + 5.0
                while answers[0] < expected:
                    if time.monotonic() > deadline:
                        raise RuntimeError('an echo process stopped answering for 5 s')
                    executor.spin_once(timeout_sec=1.0)
            blocks.append((time.perf_counter() - start) / (periods // 3) * 1e3)
        return statistics.median(blocks)
    finally:
        context.try_shutdown()
        for echo in echoes:
            stop(echo)


def _echo(name: str, scene_arg: str) -> int:
    """One echo process of ``messaging_floor``: answers every gait_state with a command."""
    import numpy as np
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.experimental import EventsExecutor
    from rclpy.parameter import Parameter

    from iceskate_bringup.scene import load_scene, scene_sources
    from iceskate_interfaces.msg import EffortCommand, GaitState
    from iceskate_sim.model.command import EMPTY, CommandValues
    from iceskate_sim.ros.effort_cdr import CommandEncoder
    from iceskate_sim.ros.node_support import LOCKSTEP_READER_QOS, STATE_QOS, spin_until
    sources = scene_sources(load_scene(scene_arg))[name]
    command = CommandValues(np.zeros(18), EMPTY, EMPTY, EMPTY, np.zeros(18 * len(sources)),
                            EMPTY, tuple(sources))
    encoder = CommandEncoder(name)
    rclpy.init()
    node = rclpy.create_node(name, parameter_overrides=[
        Parameter('use_sim_time', Parameter.Type.BOOL, True)])
    publisher = node.create_publisher(EffortCommand, 'effort_commands', STATE_QOS)

    def answer(state: bytes) -> None:  # its stamp, as the controller nodes read it
        sec, nanosec = struct.unpack_from('<iI', state, 4)
        publisher.publish(encoder.encode(command, sec * 1_000_000_000 + nanosec))
    node.create_subscription(GaitState, 'gait_state', answer, LOCKSTEP_READER_QOS, raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    try:
        spin_until(executor, lambda: False)
    except ExternalShutdownException:  # SIGTERM from messaging_floor
        pass
    return 0


if __name__ == '__main__':
    sys.exit(main())
