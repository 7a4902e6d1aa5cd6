"""Recording a run to a rosbag2 bag (MCAP) without ROS: ``BagRecorder``, which hands the native
loop's blocks to a writer process (or writes them in-process), with the run in the metadata.
See docs/architecture.md, 'Bags'.
"""

from __future__ import annotations

from collections.abc import Sequence
import contextlib
import gc
import json
import multiprocessing
from multiprocessing.connection import Connection
import os
import pathlib
import queue
import signal
from typing import Any

import numpy as np
from rosbags.typesys.store import Typestore

from iceskate_sim.errors import SimulationError
from iceskate_sim.installed import share_path
from iceskate_sim.model.robot import Robot, load_robot
from iceskate_sim.recording.bag_types import INTERFACES_PACKAGE, OFFERED_QOS, make_typestore
from iceskate_sim.recording.mcap_bag import Bag
from iceskate_sim.recording.messages import (
    RECORDED_TOPICS,
    TOPICS,
    Events,
    SampleMessages,
)
from iceskate_sim.shutdown import STOP_SIGNALS, die_with_parent

PROJECT_VERSION = '0.1.0'
QUEUE_BLOCKS = 40  # blocks in flight before ``write_block`` waits for the writer process
#: What the writer process takes: a block of samples (columns) and its rows' latest events.
Batch = tuple[dict[str, Any], Events]
#: The topics with a message at every sample of the bag; /tf has one at every ``tf_every``-th.
EVERY_SAMPLE = tuple(topic for topic in RECORDED_TOPICS if topic != '/tf')
#: The sample columns /tf messages are made of.
TF_COLUMNS = ('t', 'stamps_ns', 'tf')


class _BagFile:
    """The open bag: metadata, topics and the URDF written; encodes blocks."""

    def __init__(self, path: pathlib.Path, metadata: dict[str, Any], urdf: str,
                 messages: SampleMessages, tf_every: int = 1) -> None:
        self.messages = messages
        self.tf_every = tf_every
        self.samples = 0  # written so far
        custom = {key: value if isinstance(value, str) else json.dumps(value, sort_keys=True)
                  for key, value in metadata.items()}
        self._bag = Bag(path, TOPICS, messages.typestore, OFFERED_QOS,
                        {**custom, 'project_version': PROJECT_VERSION})
        self._bag.write('/robot_description', 0, messages.description(urdf))

    def write_block(self, block: dict[str, Any], events: Events) -> None:
        """Write the messages of a block of samples, sample by sample, in one go (/tf at
        every ``tf_every``-th sample of the run)."""
        rows = len(block['t'])
        messages = self.messages.encode(block, events, EVERY_SAMPLE)
        tf: list[bytes | None] = [None] * rows
        kept = np.flatnonzero((self.samples + np.arange(rows)) % self.tf_every == 0)
        if len(kept):
            encoded = self.messages.encode({key: block[key][kept] for key in TF_COLUMNS},
                                           events, ('/tf',))['/tf']
            for k, data in zip(kept.tolist(), encoded, strict=True):
                tf[k] = data
        messages['/tf'] = tf
        self._bag.write_instants(block['stamps_ns'][:, 0].tolist(), messages)
        self.samples += rows

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        self._bag.close()


def _sample_messages(typestore: Typestore | None, tf_frames: Sequence[tuple[str, str]]
                     ) -> SampleMessages:
    """The encoder of the recorded messages (``typestore`` None: ``make_typestore()``)."""
    return SampleMessages(typestore or make_typestore(), tf_frames)


def _writer_process(path: pathlib.Path, metadata: dict[str, Any], urdf: str,
                    encoder: tuple[Typestore | None, Sequence[tuple[str, str]]], tf_every: int,
                    batches: multiprocessing.Queue, status: Connection) -> None:
    """Body of the writer process: write the ``Batch``es of ``batches`` until None, then close
    the bag and send ('ok', samples) or ('error', message) on ``status``. Stop signals are
    left to the parent; once the parent is gone (SIGUSR1, then SIGALRM a second later), the
    batches that arrived whole are written and the bag closed (docs/architecture.md, 'Bags')."""
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    gc.freeze()  # what the parent had: not this process's garbage, never collected here
    reading, orphaned = False, False

    parent = multiprocessing.parent_process()

    def parent_gone(signum: int, frame: Any) -> None:
        nonlocal orphaned
        if signum == signal.SIGUSR1:  # the thread that forked this process ended: look again
            signal.alarm(1)  # in a second, when the rest of the parent is gone too
            return
        if parent is not None and parent.is_alive():  # only that thread ended
            return
        orphaned = True
        if reading:  # blocked on the queue: give up the read (else only note it)
            raise _ParentGone

    signal.signal(signal.SIGUSR1, parent_gone)
    signal.signal(signal.SIGALRM, parent_gone)
    die_with_parent(signal.SIGUSR1, parent.pid if parent is not None else None)
    count = 0
    try:
        bag = _BagFile(path, metadata, urdf, _sample_messages(*encoder), tf_every)
        try:
            while True:
                if orphaned:
                    signal.alarm(2)  # what is left in the queue must come within 2 s
                reading = True
                try:
                    batch = batches.get(timeout=1.0)
                except queue.Empty:
                    if orphaned or (parent is not None and not parent.is_alive()):
                        break
                    continue
                except (_ParentGone, EOFError, OSError):
                    break
                finally:
                    reading = False
                if batch is None:
                    break
                bag.write_block(*batch)
                count += len(batch[0]['t'])
        finally:
            signal.alarm(0)
            bag.close()
    except BaseException as exc:  # reported to the parent, which raises it
        with contextlib.suppress(OSError):  # unless it is gone
            status.send(('error', f'{type(exc).__name__}: {exc}'))
    else:
        with contextlib.suppress(OSError):
            status.send(('ok', count))
    finally:
        status.close()


class _ParentGone(Exception):
    """The writer's parent died while the writer waited for a batch."""


class BagRecorder:
    """Writes blocks of samples to an MCAP rosbag2 bag; closes cleanly even when a run fails.

    :param robot: the recorded robot (its links on /tf; default: ``load_robot()``, the package
        URDF's, which the callers record as /robot_description).
    :param tf_every: /tf at every n-th sample, from the first (the other topics at every one).
    :param background: encode and write the messages in a writer process, forked here (a few
        ms, no re-import of ``__main__``; the writer touches neither ROS nor the simulation, so
        threads of the parent do not matter; it imports rosbags' typestore itself, which
        CPython's fork makes safe with its import lock) and run under SCHED_IDLE: it takes only
        the CPU time the run and the ROS nodes leave. ``write_block`` hands a block over,
        waiting while ``QUEUE_BLOCKS`` are in flight, and raises SimulationError once the
        writer has failed. ``close`` waits until everything is written.
    """

    def __init__(self, path: str | pathlib.Path, metadata: dict[str, Any], urdf: str,
                 typestore: Typestore | None = None, robot: Robot | None = None,
                 background: bool = False, tf_every: int = 1) -> None:
        self.path = pathlib.Path(path)
        if self.path.exists():
            raise SimulationError(f'bag {self.path} already exists; choose another output '
                                  'directory')
        if typestore is None:  # no iceskate_interfaces: said here, not by the writer later
            share_path(INTERFACES_PACKAGE, 'msg')
        self._typestore = typestore
        self._tf_frames = (robot or load_robot()).tf_frames
        self._messages: SampleMessages | None = None
        self.count = 0
        self._bag: _BagFile | None = None
        self._process: multiprocessing.process.BaseProcess | None = None
        if not background:
            self._bag = _BagFile(self.path, metadata, urdf, self.messages, tf_every)
            return
        context = multiprocessing.get_context('fork')
        self._batches = context.Queue(maxsize=QUEUE_BLOCKS)
        self._status, child_status = context.Pipe(duplex=False)
        self._process = context.Process(
            target=_writer_process, name='bag-writer', daemon=True,
            args=(self.path, metadata, urdf, (self._typestore, self._tf_frames), tf_every,
                  self._batches, child_status))
        self._process.start()
        # the lowest priority: the writer never delays the run or a lockstep node (its queue
        # is bounded: a parent that gets ahead waits, and the writer then has the CPU)
        os.sched_setscheduler(self._process.pid, os.SCHED_IDLE, os.sched_param(0))
        child_status.close()

    @property
    def messages(self) -> SampleMessages:
        """The messages' encoder, made on first use (rosbags' Jazzy typestore takes about
        0.2 s to import): a background writer makes its own, so a headless run's process never
        imports it."""
        if self._messages is None:
            self._messages = _sample_messages(self._typestore, self._tf_frames)
        return self._messages

    def write_block(self, block: dict[str, Any], events: Events) -> None:
        """Record consecutive control instants (after those written before): a block of the
        native loop and the latest event at each of its samples."""
        if self._bag is not None:
            self._bag.write_block(block, events)
        elif self._process is not None:
            self._hand_over((block, events))
        else:
            raise SimulationError(f'bag {self.path} is closed')
        self.count += len(block['t'])

    def _hand_over(self, item: Batch | None) -> None:
        """Queue a batch (None: the end) for the writer process, waiting while it is busy."""
        self._check_writer()
        while True:
            try:
                self._batches.put(item, timeout=0.2)
                return
            except queue.Full:
                self._check_writer()

    def _check_writer(self) -> None:
        """Raise SimulationError if the writer process has failed or ended early."""
        if self._status.poll() or not self._process.is_alive():
            process, self._process = self._process, None
            process.join(timeout=5.0)
            self._batches.cancel_join_thread()
            raise SimulationError(f'bag writer for {self.path} failed: '
                                  f'{self._writer_status(process)}', end='io_error')

    def _writer_status(self, process: multiprocessing.process.BaseProcess) -> str:
        """The writer's report ('ok' or the error), or its exit code if it sent none."""
        if self._status.poll():
            try:
                kind, detail = self._status.recv()
                return 'ok' if kind == 'ok' else detail
            except EOFError:
                pass
        return f'writer process exited with code {process.exitcode}'

    def close(self) -> None:
        """Finish the bag (idempotent); a background writer first writes all it was given.

        :raises SimulationError: if the background writer failed.
        """
        if self._bag is not None:
            self._bag.close()
            self._bag = None
        if self._process is None:
            return
        self._hand_over(None)
        process, self._process = self._process, None
        process.join()
        self._batches.cancel_join_thread()  # what a failed writer left unread stays unread
        self._batches.close()
        status = self._writer_status(process)
        if status != 'ok':
            raise SimulationError(f'bag writer for {self.path} failed: {status}', end='io_error')

    def __enter__(self) -> BagRecorder:
        """Context manager: the bag is closed on exit, also after an exception."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the bag."""
        self.close()
