#!/usr/bin/env python3
"""The bag writer's work per control instant: rosbags' Writer.write one message at a time
against ``mcap_bag.Bag.write_instants`` (a whole block at once), on the blocks of a real run.

Runs a scene headless (no bag) for ``--duration`` s and keeps the blocks of
samples the runner hands to its bag writer; then, ``--rounds`` times in turn, writes them into a
fresh MCAP bag in this process the way the writer process does (``_BagFile.write_block``: the
block encoded, then its messages written), once per message through rosbags' ``Writer.write``
and once through ``Bag.write_instants``, checks that the two bags hold the same messages (read
back with rosbags), and prints microseconds per
control instant (medians over the rounds) and their ratio, all measured in this one run. The
writer process must keep up with the native loop (about 30 us a period here) or the run waits
for it at the end.

Usage (from the repository root, environment sourced; no other benchmark running):
    python benchmarks/bench_bag_write.py [skate] [--duration 15] [--rounds 3]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import pathlib
import statistics
import tempfile
import time

from bench_work_precision import machine_info
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene
from iceskate_sim.recording import bag as recording
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.messages import RECORDED_TOPICS, TOPICS, Events, SampleMessages
from iceskate_sim.run.session import Session, scene_metadata

WAYS = ('Writer.write, message by message', 'Bag.write_instants, block by block')


class _Blocks:
    """Stands in for the session's bag recorder: keeps the blocks it is handed."""

    def __init__(self) -> None:
        self.blocks: list[tuple[dict, Events]] = []

    def write_block(self, block: dict, events: Events) -> None:
        self.blocks.append((block, events))

    def close(self) -> None:
        pass


def _one_by_one(path: pathlib.Path, messages: SampleMessages, urdf: str,
                blocks: list[tuple[dict, Events]]) -> None:
    """The bag through rosbags' public writer: every message through ``Writer.write``."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {topic: writer.add_connection(topic, msgtype,
                                                    typestore=messages.typestore)
                       for topic, msgtype in TOPICS.items()}
        writer.write(connections['/robot_description'], 0, messages.description(urdf))
        for block, events in blocks:
            encoded = messages.encode(block, events)
            columns = [(connections[topic], encoded[topic]) for topic in RECORDED_TOPICS]
            for k, ns in enumerate(block['stamps_ns'][:, 0].tolist()):
                for connection, column in columns:
                    writer.write(connection, ns, column[k])


def _write(path: pathlib.Path, scene: object, session: Session, messages: SampleMessages,
           blocks: list[tuple[dict, Events]], way: str) -> float:
    """Seconds to write ``blocks`` into a new bag at ``path`` (opening and closing it)."""
    urdf = session.robot.urdf_path.read_text(encoding='utf-8')
    start = time.perf_counter()
    if way == WAYS[0]:
        _one_by_one(path, messages, urdf, blocks)
    else:
        bag = recording._BagFile(path, scene_metadata(scene), urdf, messages)
        for block in blocks:
            bag.write_block(*block)
        bag.close()
    return time.perf_counter() - start


def _messages(path: pathlib.Path) -> list[tuple[str, int, bytes]]:
    """The bag's messages in order: (topic, stamp [ns], data)."""
    with Reader(path) as reader:
        return [(connection.topic, stamp, bytes(data))
                for connection, stamp, data in reader.messages()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scene', nargs='?', default='skate')
    parser.add_argument('--duration', type=float, default=15.0, help='simulated seconds')
    parser.add_argument('--rounds', type=int, default=3, help='writes of each way (median)')
    args = parser.parse_args()
    info = machine_info()
    scene = replace(load_scene(args.scene), duration=args.duration, record_bag=False)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    session.recorder = recorder = _Blocks()
    while not session.done:
        session.run_periods(stack, 1000)
    session.finish()
    samples = sum(len(block['t']) for block, _ in recorder.blocks)
    messages = SampleMessages(make_typestore(), session.robot.tf_frames)
    for block, events in recorder.blocks:  # the layouts of every message, as in a writer
        messages.encode(block, events)
    times: dict[str, list[float]] = {way: [] for way in WAYS}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            paths = {}
            for i, way in enumerate(WAYS):
                paths[way] = pathlib.Path(tmp) / f'{k}-{i}' / 'bag'
                paths[way].parent.mkdir()
                times[way].append(_write(paths[way], scene, session, messages, recorder.blocks,
                                         way))
            if _messages(paths[WAYS[0]]) != _messages(paths[WAYS[1]]):
                raise SystemExit('the two ways wrote different messages')
    print(f'{args.scene}, {args.duration:g} s: {samples} control instants, '
          f'{len(RECORDED_TOPICS)} messages each; median of {args.rounds} rounds, '
          'ways in turn; the two bags hold the same messages')
    print(f'machine: {info["cpu"]}, {info["cpus"]} CPUs; load average at start '
          f'{info["loadavg_start"]}; {info["date"]}')
    per = {way: statistics.median(times[way]) / samples * 1e6 for way in WAYS}
    for way in WAYS:
        print(f'{way:36s} {per[way]:7.1f} us per control instant (encoding included)')
    print(f'ratio: write_instants takes {per[WAYS[1]] / per[WAYS[0]]:.2f} of the time '
          f'({per[WAYS[0]] / per[WAYS[1]]:.2f}x faster)')


if __name__ == '__main__':
    main()
