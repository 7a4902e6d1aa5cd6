"""One run of a scene, ROS-free: ``Session``, the loop that the headless runner (``run_periods``)
and the simulator node (``hold``) share, so both give the same trajectory; the output folder
(``prepare_output``). See docs/architecture.md, 'The data path of a run'.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import asdict
import fcntl
import json
import os
import pathlib
import tempfile
import time
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from iceskate_native.sample import SAVED_COLUMNS
from iceskate_sim.disk import Room, write_atomically
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import Robot, load_robot
from iceskate_sim.physics.simulation import Simulator
from iceskate_sim.recording.bag import BagRecorder
from iceskate_sim.recording.messages import Events
from iceskate_sim.run.metrics import Trajectory, compute_metrics
from iceskate_sim.run.scene import Scene

if TYPE_CHECKING:
    from iceskate_native import Controller, Kinematics
    from iceskate_sim.physics.simulation import NativeControlLoop

#: Samples of held periods (``Session.hold``) recorded at once by a partial ``flush``.
HELD_BLOCK = 100


class Controllers(Protocol):
    """The controllers of a run in one process (``iceskate_bringup.composition.ControlStack``):
    the native laws by node name in summing order and their kinematics."""

    controllers: Mapping[str, Controller]
    kinematics: Kinematics


def scene_metadata(scene: Scene) -> dict[str, str]:
    """Bag custom_data: scene name, its full parameters, the integrator."""
    return {'scene': scene.name, 'scene_parameters': json.dumps(scene.raw, sort_keys=True),
            'integrator': json.dumps(asdict(scene.simulator.integrator), sort_keys=True)}


#: The lock file of an output directory, held by the one run that writes into it.
LOCK_NAME = '.run.lock'
#: Disk [bytes] a run keeps in its output directory from its start for metrics.json (its
#: 600 s run's is 0.2 MB) and for events.json (grown with the events: a 15 s skate run's 245
#: take 48 kB), written into it at the end: a full disk ends the run with both written.
METRICS_ROOM = 1 << 20
EVENTS_ROOM = 64 << 10
EVENT_ROOM = 512  # per event
#: How a launcher hands its lock on the output directory to the simulator process it starts:
#: the number of the inherited descriptor.
LOCK_FD_ENV = 'ICESKATE_OUTPUT_LOCK_FD'
#: The output directories this process holds, by resolved path: their lock descriptors.
_HELD: dict[pathlib.Path, int] = {}


def prepare_output(out: pathlib.Path, bag: pathlib.Path | None = None,
                   resumes: str | None = None, made: tuple[str, ...] = ()) -> int:
    """Create the output directory ``out`` (with its parents), check that a run can write into
    it, take it for this run (an exclusive lock on ``out/.run.lock``, kept until
    ``release_output`` or the end of the process; a lock this process or its launcher holds
    already is taken as it is) and check that it holds no finished run, that the bag path
    ``bag`` (if any) is free and that it holds nothing else: a run writes only files it makes.
    ``resumes``: the file that marks an earlier run of the caller's own kind, which it goes on
    with (a sweep's table): a folder holding it need not be empty. ``made``: entries the run's
    launcher made in it for this run (the nodes' ``params`` of a graph). Returns the lock's
    descriptor.

    :raises InputRefused: one sentence naming the path and the problem (a file in the way,
        no permission, a read-only file system, another run writing there, an earlier run's
        bag or metrics, files the run did not make).
    """
    out = pathlib.Path(out)
    for path in (out, *out.parents):
        if path.exists() or path.is_symlink():
            if not path.is_dir():
                where = 'is' if path == out else f'lies under {path}, which is'
                raise InputRefused(f'output directory {out} {where} an existing file, not '
                                   'a directory')
            break
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputRefused(f'output directory {out} cannot be created: '
                           f'{_reason(exc)}') from None
    try:
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise InputRefused(f'output directory {out} is not writable: {_reason(exc)}') \
            from None
    taken = out.resolve() in _HELD or _launcher_lock(out) is not None  # its files: this run's
    lock = out / LOCK_NAME
    if lock.is_symlink() or (lock.exists() and not lock.is_file()):
        raise InputRefused(f'output directory {out} holds {LOCK_NAME!r}, which is not a '
                           "run's lock file; choose another output directory")
    # a folder of a run of ours (its lock file) is locked first: "in use" if it runs still;
    # any other is checked before a lock file is made in it
    fd = _lock(out) if taken or lock.exists() else None
    try:
        for earlier in ([bag] if bag is not None else []) + [out / 'metrics.json']:
            if earlier.exists() or earlier.is_symlink():
                raise InputRefused(f'output directory {out} already holds a recorded run: '
                                   f'{earlier} already exists; choose another output '
                                   'directory')
        earlier_kind = resumes is not None and (out / resumes).is_file()
        others = ([] if taken or earlier_kind else
                  sorted(name for name in os.listdir(out) if name not in (LOCK_NAME, *made)))
        if others:  # a run writes only files it makes: never over (or through) the user's
            raise InputRefused(f'output directory {out} is not empty (it holds '
                               f'{others[0]!r}{" and more" if len(others) > 1 else ""}): a '
                               'run writes only into a new or empty directory; choose '
                               'another output directory')
    except InputRefused:
        release_output(out)
        raise
    return fd if fd is not None else _lock(out)


def _launcher_lock(out: pathlib.Path) -> int | None:
    """The descriptor of the lock on ``out`` this process inherited from its launcher (None:
    none)."""
    try:
        fd = int(os.environ.get(LOCK_FD_ENV, ''))
        held, there = os.fstat(fd), os.stat(out / LOCK_NAME)
    except (ValueError, OSError):
        return None
    return fd if (held.st_dev, held.st_ino) == (there.st_dev, there.st_ino) else None


def _lock(out: pathlib.Path) -> int:
    """The descriptor of this process's exclusive lock on ``out`` (taken now if need be)."""
    path, key = out / LOCK_NAME, out.resolve()
    if key in _HELD:
        return _HELD[key]
    fd = _launcher_lock(out)
    if fd is not None:
        _HELD[key] = fd  # the launcher's, inherited
        return fd
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise InputRefused(f'output directory {out} cannot be locked: {_reason(exc)}') \
            from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise InputRefused(f'output directory {out} is in use by another run; choose '
                           'another output directory or wait until that run ends') from None
    _HELD[key] = fd
    return fd


def release_output(out: pathlib.Path) -> None:
    """Give up this process's lock on ``out`` (if it holds one)."""
    fd = _HELD.pop(pathlib.Path(out).resolve(), None)
    if fd is not None:
        os.close(fd)


def _rows(block: dict[str, Any], kept: np.ndarray) -> dict[str, Any]:
    """The rows of a native block where ``kept`` (a mask or indices) holds."""
    rows = {key: value[kept] if isinstance(value, np.ndarray) else value
            for key, value in block.items()}
    rows['efforts'] = [e[kept] for e in block['efforts']]
    return rows


def _reason(exc: OSError) -> str:
    """An OSError's reason in words (e.g. 'permission denied')."""
    text = exc.strerror or str(exc)
    return text[:1].lower() + text[1:]


def start_simulator(scene: Scene, robot: Robot) -> Simulator:
    """The simulator of ``scene`` at its initial state.

    :raises InputRefused: for settings or an initial state the kernel refuses, or one the run
        would end in at once (e.g. a foot below the floor: nothing to simulate), naming its
        mode and the reason.
    """
    sim = Simulator(robot, scene.simulator, scene.initial)
    if sim.ended is not None:
        raise InputRefused(_unstartable(scene, sim, ''))
    return sim


def _unstartable(scene: Scene, sim: Simulator, under: str) -> str:
    """Why an initial state ends the run at once (``under``: the input that makes it do so,
    '' for none)."""
    return (f'scene {scene.name!r}: the initial state cannot be simulated{under}, it ends the '
            f'run at once from mode {scene.initial.mode.number} ({sim.ended}); change '
            'initial.posture, initial.q, initial.v or initial.mode')


class Session:
    """One run of ``scene``.

    :param scene: the validated scene (its ``duration`` is the run length).
    :param out: directory for metrics.json, events.json and trajectory.npz (None: none).
    :param bag: path of the MCAP bag to record (None: none).
    :param robot: the robot model (loaded if None).
    :param made: entries of ``out`` the run's launcher made for it (``prepare_output``).
    """

    def __init__(self, scene: Scene, out: pathlib.Path | None = None,
                 bag: pathlib.Path | None = None, robot: Robot | None = None,
                 made: tuple[str, ...] = ()) -> None:
        self.scene = scene
        self.out = out
        self.robot = robot or load_robot()
        self.sim = start_simulator(scene, self.robot)
        self.n_periods = int(round(scene.duration / scene.simulator.control_period))
        if out is not None:
            prepare_output(out, bag, made=made)
        #: the disk kept for metrics.json and events.json (none without ``out``)
        self._rooms: dict[str, Room] = {}
        try:
            if out is not None:
                try:
                    for name, size in (('metrics.json', METRICS_ROOM),
                                       ('events.json', EVENTS_ROOM)):
                        self._rooms[name] = Room(out / f'.{name}.room', size)
                except OSError as exc:
                    raise SimulationError(f'output directory {out} has no room for the '
                                          f'metrics ({(METRICS_ROOM + EVENTS_ROOM) >> 10} '
                                          f'KiB): {_reason(exc)}', end='io_error') from None
            self.recorder = (BagRecorder(bag, scene_metadata(scene),
                                         self.robot.urdf_path.read_text(encoding='utf-8'),
                                         background=True, tf_every=scene.tf_every)
                             if bag is not None else None)
        except BaseException:
            for room in self._rooms.values():
                room.release()
            if out is not None:
                release_output(out)
            raise
        self.metrics: dict[str, Any] | None = None
        #: the trajectory columns of the block recorded last (None: none yet)
        self.latest: dict[str, np.ndarray] | None = None
        #: the native loop holding commands received from outside (``command_inbox``)
        self._inbox: NativeControlLoop | None = None
        self._restart()

    def _restart(self) -> None:
        obs = self.sim.observation()
        #: head pose at t = 0 (y, z, pitch): the target recorded where no controller sets one
        self.psi_initial = self.sim.dynamics.head_pose(obs.contact(), obs.q)[0]
        # a long run's samples go to files beside its outputs (or in the temporary directory)
        self.trajectory = Trajectory(self.out if self.out is not None
                                     else pathlib.Path(tempfile.gettempdir()))
        self.periods = 0
        self.error: SimulationError | None = None
        self._wall_start: float | None = None
        #: the native loop of ``run_periods`` (None: not made yet)
        self._loop: NativeControlLoop | None = None
        if self._inbox is not None:  # the samples and commands of the run left behind
            self._inbox.kernel.take_block()
            self._inbox.kernel.forget()

    @property
    def done(self) -> bool:
        """The run is over: duration reached, physically ended, or failed."""
        return (self.periods >= self.n_periods or self.sim.ended is not None
                or self.error is not None)

    def observation(self) -> Observation:
        """What the controllers see at t_k (times at the stamps' nanosecond resolution)."""
        return self.sim.observation()

    def command_inbox(self, inbox: tuple[tuple[str, ...], ...],
                      renew: bool = False) -> NativeControlLoop:
        """The native loop that holds commands received from outside (``hold``): ``inbox`` has
        the sources of each controller node in summing order; ``receive`` a node's command by
        its index. ``renew``: a new one (for a new ``inbox``; the commands held are dropped)."""
        if self._inbox is None or renew:
            self._inbox = self.sim.control_loop(None, [], self.scene.pushes, self.psi_initial,
                                                inbox)
        return self._inbox

    def hold(self, clear: bool = True) -> bool:
        """One control period holding the commands received by the ``command_inbox`` loop (the
        same sum, hold, push and sample as ``run_periods``), its sample recorded by a later
        ``flush``; ``clear``: forget the commands afterwards. False if the run is done; a
        SimulationError of the physics ends the run (``error``)."""
        if self.done:
            return False
        if self._wall_start is None:
            self._wall_start = time.perf_counter()
        try:
            self.sim.hold_period(self._inbox, clear)
        except SimulationError as exc:
            self.error = exc
            return False
        self.periods += 1
        return True

    def run_periods(self, stack: Controllers, count: int) -> int:
        """Advance up to ``count`` control periods with ``stack``'s laws answering each
        observation in C++ (the headless runner), recording every sample; return how many were
        taken.

        The whole block is one call of the native control loop (``Simulator.control_loop``:
        the laws, the sum of their commands, the hold, the push and the period, with no Python
        in between). A failure of the physics, or of writing the samples (a full disk), ends
        the run (``error``); a controller's own error is raised once the samples before it are
        recorded.
        """
        if self.done:
            return 0
        if self._wall_start is None:
            self._wall_start = time.perf_counter()
        if self._loop is None:
            self._loop = self.sim.control_loop(stack.kinematics, list(stack.controllers.values()),
                                               self.scene.pushes, self.psi_initial)
        block, error = self.sim.run_loop(self._loop, min(count, self.n_periods - self.periods))
        taken = len(block['t'])
        if taken:
            try:
                self._record_block(block, self.periods)
            except SimulationError as exc:  # the bag's or the trajectory's files: the run ends
                error = exc if not isinstance(error, SimulationError) else error
            self.periods += taken
        if isinstance(error, SimulationError):
            self.error = error
        elif error is not None:
            raise error
        return taken

    def _record_block(self, block: dict[str, Any], first: int) -> None:
        """Append a native block of samples, the first of period ``first``, to the trajectory
        and the bag."""
        periods = first + np.arange(len(block['t']))
        if self.scene.record_every > 1:  # record.rate: every n-th sample only
            kept = periods % self.scene.record_every == 0
            block, periods = _rows(block, kept), periods[kept]
        columns = {key: block[key] for key in SAVED_COLUMNS}
        for key, values in columns.items():  # the saved trajectory's integers are int64
            if values.dtype == np.int32:
                columns[key] = values.astype(np.int64)
        columns['psi'] = np.column_stack([block['head_position'][:, 1:], block['head_pitch']])
        self.trajectory.extend(columns, dict(zip(block['sources'], block['efforts'],
                                                 strict=True)))
        self.latest = columns
        if 'events.json' in self._rooms:
            try:
                self._rooms['events.json'].grow(EVENTS_ROOM + EVENT_ROOM * len(self.sim.events))
            except OSError as exc:
                raise SimulationError(f'no room left on disk for {self.out / "events.json"}: '
                                      f'{_reason(exc)}', end='io_error') from None
        if self.recorder is not None:
            if self.scene.bag_every > 1:  # record.bag_rate: every n-th recorded sample
                block = _rows(block, periods % (self.scene.record_every
                                                * self.scene.bag_every) == 0)
            if len(block['t']):
                self.recorder.write_block(block, Events.of(block['last_event'],
                                                           self.sim.events))

    def flush(self, whole: bool = True) -> None:
        """Append the samples held since the last flush to the trajectory and the bag
        (``whole``: all of them; else only once a block of ``HELD_BLOCK`` has gathered: one
        block of arrays costs what a few samples do)."""
        inbox = self._inbox
        if inbox is not None and inbox.kernel.block_size >= (1 if whole else HELD_BLOCK):
            first = self.periods - inbox.kernel.block_size
            self._record_block(inbox.kernel.take_block(), first)

    def reset(self) -> None:
        """Back to the scene's initial state (refused while recording a bag)."""
        if self.recorder is not None:
            raise SimulationError('a reset is refused while the run is recorded to a bag')
        self.sim.reset()
        self.metrics = None
        self._restart()

    def finish(self, error: SimulationError | None = None,
               extra: Mapping[str, Any] | None = None,
               written: Callable[[], None] | None = None) -> dict[str, Any]:
        """End the run (once): write the trajectory, compute the metrics, write the output
        files, close the bag.

        :param error: why the run was ended from outside (kept unless the physics failed;
            a ``RunInterrupted`` for a signal).
        :param extra: more entries for the metrics (e.g. the rejected commands of a ROS run).
        :param written: called once the output files are written, while the bag writer
            finishes (e.g. to draw the summary); again if closing the bag then fails (the
            metrics then say so).
        """
        if self.metrics is not None:
            return self.metrics
        if error is not None and self.error is None:
            self.error = error
        if self.error is None and self.sim.ended is not None and self.sim.time == 0.0:
            # not a fall: a posture the controllers' first command cannot hold on the floor
            self.error = SimulationError(_unstartable(
                self.scene, self.sim, " under the controllers' first command"))
        output_error: SimulationError | None = None  # an output that could not be written
        try:
            self.flush()
        except SimulationError as exc:  # the bag failed: the other outputs are still written
            output_error = exc
        closed: SimulationError | None = None
        try:
            if self.out is not None:
                saved = self._save_trajectory()
                output_error = output_error or saved
            self._write_metrics(extra, output_error)
            if written is not None:
                written()
        finally:  # the bag is closed whatever happens before
            for room in self._rooms.values():
                room.release()
            if self.recorder is not None:
                try:
                    self.recorder.close()
                except SimulationError as exc:
                    closed = exc
        if closed is not None and output_error is None and self.error is None:
            self._write_metrics(extra, closed)
            if written is not None:
                written()
        if self.out is not None:
            release_output(self.out)
        return self.metrics

    def _save_trajectory(self) -> SimulationError | None:
        """Write trajectory.npz; a failure to write (a full disk) is returned, the partial
        file removed (unreadable, and its room is the metrics')."""
        path = self.out / 'trajectory.npz'
        try:
            self.trajectory.save(path)
        except (OSError, SimulationError) as exc:  # SimulationError: its spilled columns
            path.unlink(missing_ok=True)
            reason = _reason(exc) if isinstance(exc, OSError) else str(exc)
            return SimulationError(f'cannot write {path}: {reason}', end='io_error')
        return None

    def _write_metrics(self, extra: Mapping[str, Any] | None,
                       output_error: SimulationError | None) -> None:
        """Write events.json, compute the metrics (an output that could not be written is the
        run's error unless it has one) and write metrics.json, each whole or not at all.

        :raises SimulationError: when metrics.json cannot be written.
        """
        if output_error is not None and self.error is None:
            self.error = output_error
        if self.out is not None:
            try:
                self._write_output('events.json', json.dumps(
                    [asdict(e) for e in self.sim.events], indent=1, default=float))
            except SimulationError as exc:
                self.error = self.error or exc
        start = self._wall_start if self._wall_start is not None else time.perf_counter()
        self.metrics = compute_metrics(self.scene, self.sim, self.trajectory,
                                       time.perf_counter() - start, self.error)
        self.metrics.update(extra or {})
        if self.out is not None:
            self._write_output('metrics.json', json.dumps(self.metrics, indent=2))

    def _write_output(self, name: str, text: str) -> None:
        """Write ``text`` as the file ``name`` of the output directory, whole or not at all,
        into the room kept for it (the first time).

        :raises SimulationError: (``io_error``) when it cannot be written.
        """
        data, path = (text + '\n').encode(), self.out / name
        try:
            room = self._rooms.pop(name, None)
            if room is not None:
                room.write(path, data)
            else:
                write_atomically(path, data)
        except OSError as exc:
            raise SimulationError(f'cannot write {path}: {_reason(exc)}',
                                  end='io_error') from None
