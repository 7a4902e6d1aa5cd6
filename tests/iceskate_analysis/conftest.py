"""Bags for the offline-analysis tests, generated in temporary directories (never committed).

* ``sim_bag``: a short run of a tiny ice-skating scene (torso-yaw input on) through the headless
  runner, i.e. the bag our runs really write.
* ``synthetic_bag`` / ``synthetic_no_yaw_bag``: bags written by ``BagRecorder.write_block``
  from one block of samples in the native loop's columns (``synthetic_block``), of prescribed
  states that visit modes 1, 2 (q1 active, heel pivot), 3 (y0 active) and 5 (sliding swing
  heel) on both support sides, four steps long, with the arms swinging as prescribed sinusoids
  (anti-phase with the yaw source, nearly in phase without). Their accelerations are
  ``GaitDynamics.evaluate`` at each state, so eq. (11) must close on them exactly as on a run;
  the head-top pose is the oracle's, the root link's world pose Pinocchio's in the support
  model.
* ``bag_without``: a copy of a bag with one topic left out; ``truncated_bag``: a copy cut short.
* ``saved_figures``: every matplotlib figure saved during a test, by file name
  (``record_figures``: the same as a context manager); ``legends_clear``: asserts a figure's
  legends are clear of its axes, texts and each other.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
import contextlib
import itertools
import pathlib
import shutil
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import (
    N_COORDINATES,
    PIVOTS,
    Q1,
    SIDES,
    SOLE_HEEL_Y,
    SOLE_TOE_Y,
    Y0,
    load_robot,
)
from iceskate_sim.model.stamps import seconds_to_ns
from iceskate_sim.recording.bag import BagRecorder
from iceskate_sim.recording.messages import Events
from oracle.dynamics import GaitDynamics
from oracle.tf import tf_rows

#: A tiny version of the skate scene: ice, visual lifting, posture and the torso-yaw input.
TINY_SKATE = {
    'scene': 'tiny_skate',
    'duration': 0.04,
    'control_period': 0.001,
    'floor': {'rule': 'ice', 'mu': 0.005},
    'initial': {'mode': 17, 'support': 'right', 'posture': 'bent_knees', 'knee_bend': 0.05,
                'v': {'q8': 0.4, 'q11': 0.5, 'q14': -0.5}},
    'integrator': {'method': 'rk4', 'step': 0.0005},
    'inputs': {'visual_lifting': {'desired_y': 'moving', 'v_d': 0.3},
               'gait_manager': {'enabled': ['posture', 'yaw']}},
    'record': {'bag_rate': None},  # every period in the bag: compared sample by sample
}
#: (mode, support side, pivot) of each synthetic step.
SYNTHETIC_STEPS = ((1, 'right', 'toe'), (2, 'left', 'heel'), (3, 'right', 'toe'),
                   (5, 'left', 'toe'))
SAMPLES_PER_STEP = 40
DT = 0.001  # s
ARM_FREQUENCY = 100.0  # Hz: 4 periods per synthetic step
ARM_AMPLITUDE = 0.3  # rad (with yaw: q11 = A sin, q14 = -A sin)
NO_YAW_AMPLITUDE = 0.05  # rad (without yaw: q14 leads q11 by NO_YAW_LEAD)
NO_YAW_LEAD = 0.5  # rad


@pytest.fixture(scope='session')
def spec() -> SimpleNamespace:
    """The constants the bags above were made with (tests cannot import conftest)."""
    return SimpleNamespace(tiny_skate=TINY_SKATE, steps=SYNTHETIC_STEPS,
                           samples_per_step=SAMPLES_PER_STEP, dt=DT,
                           arm_frequency=ARM_FREQUENCY, arm_amplitude=ARM_AMPLITUDE,
                           no_yaw_amplitude=NO_YAW_AMPLITUDE, no_yaw_lead=NO_YAW_LEAD)


@pytest.fixture(scope='session')
def sim_bag(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """A 40 ms run of TINY_SKATE recorded by the headless runner; returns the bag directory."""
    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import parse_scene
    out = tmp_path_factory.mktemp('sim_run')
    run(parse_scene(dict(TINY_SKATE)), out, progress=False)
    return out / 'bag'


def _synthetic_state(k: int, yaw: bool) -> tuple[float, int, ContactState, np.ndarray,
                                                np.ndarray]:
    step = k // SAMPLES_PER_STEP
    number, side, pivot = SYNTHETIC_STEPS[step]
    mode = get_mode(number)
    t = k * DT
    w = 2.0 * np.pi * ARM_FREQUENCY
    q = np.zeros(N_COORDINATES)
    v = np.zeros(N_COORDINATES)
    a = 0.05
    q[2:8] = (-a, 2 * a, -a, a + 0.2, -2 * a - 0.3, a + 0.1)
    q[Y0], v[Y0] = 0.3 * t, 0.3
    if mode.q1_active:
        q[Q1], v[Q1] = 0.05 + 0.2 * t, 0.2
    q[8], v[8] = 0.2 * np.sin(w * t / 4), 0.2 * w / 4 * np.cos(w * t / 4)
    if yaw:
        q[11], v[11] = ARM_AMPLITUDE * np.sin(w * t), ARM_AMPLITUDE * w * np.cos(w * t)
        q[14], v[14] = -q[11], -v[11]
    else:
        q[11] = NO_YAW_AMPLITUDE * np.sin(w * t)
        v[11] = NO_YAW_AMPLITUDE * w * np.cos(w * t)
        q[14] = NO_YAW_AMPLITUDE * np.sin(w * t + NO_YAW_LEAD)
        v[14] = NO_YAW_AMPLITUDE * w * np.cos(w * t + NO_YAW_LEAD)
    q[12], v[12] = 0.4, 0.1  # elbows bent (inside their soft stops)
    q[15], v[15] = 0.4, -0.1
    if not mode.y0_active:
        v[Y0] = 0.0
    contact = ContactState(mode, side, pivot)
    return t, step, contact, q, v


def synthetic_block(robot, yaw: bool) -> dict:
    """The synthetic samples as the native loop's block of samples (``ControlLoop.run``'s
    columns): dynamics by ``GaitDynamics.evaluate``, the head-top placement by its
    ``frame_placement``, the /tf rows by Pinocchio in the support model (``oracle.tf``)."""
    dyn = GaitDynamics(robot)
    rows: dict[str, list] = {}
    sources = ['visual_lifting', 'yaw'] if yaw else ['visual_lifting']
    efforts = {name: [] for name in sources}
    joints = np.arange(N_COORDINATES)
    for k in range(len(SYNTHETIC_STEPS) * SAMPLES_PER_STEP):
        t, step, contact, q, v = _synthetic_state(k, yaw)
        if contact.mode.swing_sliding:  # the simulator slides the heel along its velocity
            heel_vy = dyn.frame_velocity(contact, q, v, 'swing_heel').linear[1]
            contact.heel_slide_dir = float(np.sign(heel_vy)) or 1.0
        acting = {'visual_lifting': np.where(joints >= 2, 3.0 * np.sin(40.0 * t + joints), 0.0)}
        if yaw:
            acting['yaw'] = np.where(joints == 8, 30.0 * np.sin(20.0 * t), 0.0)
        result = dyn.evaluate(contact, q, v, np.sum(list(acting.values()), axis=0))
        head = dyn.frame_placement(contact, q, 'head_top')
        R = head.rotation
        pitch = np.arctan2(-R[1, 2], R[2, 2])
        row = {
            't': t, 't_exchange': 0.0, 't_touchdown': np.nan,
            'heel_anchor_y': contact.heel_anchor_y, 'mode': contact.mode.number,
            'side': SIDES.index(contact.side),
            'pivot': 1 + PIVOTS.index(contact.pivot) if contact.mode.q1_active else 0,
            'step_index': step, 'q': q, 'v': v, 'qdd': result.qdd,
            'passive': result.passive, 'applied': result.applied,
            'multipliers': result.multipliers, 'support_normal': result.support_normal,
            'support_friction': result.support_friction, 'zmp_y': result.zmp_y,
            'swing_clearance': min(result.swing_heel[2], result.swing_toe_z),
            'head_position': head.translation.copy(),
            'head_orientation': pin.Quaternion(R).coeffs().copy(), 'head_pitch': pitch,
            'tf': tf_rows(robot, contact.side, contact.pivot, q).ravel(),
            'head_target': (head.translation[1], head.translation[2], pitch),
            'last_event': -1, 'present': (1 << len(sources)) - 1,
            'stamps_ns': [seconds_to_ns(t), 0, 0, 0],
            'y0_active': contact.mode.y0_active, 'q1_active': contact.mode.q1_active,
            'zmp_inside_support': (not contact.mode.q1_active and q[Y0] + SOLE_HEEL_Y
                                   <= result.zmp_y <= q[Y0] + SOLE_TOE_Y),
            'touched_down': False, 'active': np.isin(joints, contact.mode.active),
            'effort_total': np.sum(list(acting.values()), axis=0)}
        for key, value in row.items():
            rows.setdefault(key, []).append(value)
        for name in sources:
            efforts[name].append(acting[name])
    integers = {'mode': np.int32, 'side': np.int32, 'pivot': np.int32,
                'step_index': np.int32, 'last_event': np.int64, 'present': np.uint64,
                'stamps_ns': np.int64, 'y0_active': np.uint8, 'q1_active': np.uint8,
                'zmp_inside_support': np.uint8, 'touched_down': np.uint8, 'active': np.uint8}
    block = {key: np.array(values, dtype=integers.get(key, np.float64))
             for key, values in rows.items()}
    block['sources'] = sources
    block['efforts'] = [np.array(efforts[name]) for name in sources]
    return block


def write_synthetic_bag(path: pathlib.Path, yaw: bool) -> pathlib.Path:
    """Write the synthetic bag described in the module docstring; return its directory."""
    robot = load_robot()
    scene = 'synthetic_yaw' if yaw else 'synthetic_no_yaw'
    metadata = {'scene': scene, 'scene_parameters': {'scene': scene,
                                                     'floor': {'rule': 'ice', 'mu': 0.005}}}
    block = synthetic_block(robot, yaw)
    with BagRecorder(path, metadata, robot.urdf_path.read_text(encoding='utf-8'),
                     robot=robot) as recorder:
        recorder.write_block(block, Events.of(block['last_event'], []))
    return path


@pytest.fixture(scope='session')
def synthetic_bag(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Synthetic bag with the torso-yaw source and anti-phase arms."""
    return write_synthetic_bag(tmp_path_factory.mktemp('synthetic') / 'bag', yaw=True)


@pytest.fixture(scope='session')
def synthetic_no_yaw_bag(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Synthetic bag without the yaw source, arms small and nearly in phase."""
    return write_synthetic_bag(tmp_path_factory.mktemp('synthetic_no_yaw') / 'bag', yaw=False)


@pytest.fixture
def bag_without(tmp_path: pathlib.Path) -> Callable[[pathlib.Path, str], pathlib.Path]:
    """``bag_without(bag, topic)``: a copy of ``bag`` with every message of ``topic`` left out."""
    def copy(source: pathlib.Path, topic: str) -> pathlib.Path:
        from rosbags.highlevel import AnyReader
        from rosbags.rosbag2 import StoragePlugin, Writer
        target = tmp_path / f'without_{topic.strip("/")}'
        with AnyReader([source]) as reader:
            writer = Writer(target, version=9, storage_plugin=StoragePlugin.MCAP)
            writer.open()
            try:
                out = {c.id: writer.add_connection(c.topic, c.msgtype,
                                                   typestore=reader.typestore)
                       for c in reader.connections if c.topic != topic}
                for conn, stamp, raw in reader.messages():
                    if conn.id in out:
                        writer.write(out[conn.id], stamp, raw)
            finally:
                writer.close()
        return target
    return copy


@pytest.fixture
def truncated_bag(tmp_path: pathlib.Path, sim_bag: pathlib.Path) -> pathlib.Path:
    """A copy of ``sim_bag`` whose MCAP file lost its second half (an interrupted copy)."""
    target = tmp_path / 'truncated'
    shutil.copytree(sim_bag, target)
    (mcap,) = target.glob('*.mcap')
    size = mcap.stat().st_size
    with mcap.open('r+b') as stream:
        stream.truncate(size // 2)
    return target


@contextlib.contextmanager
def recording_figures() -> Iterator[dict[str, object]]:
    """Within: every ``Figure.savefig`` records the figure under its file's name (a staged
    output's, ``.name.partial.png``, as ``name.png``)."""
    from matplotlib.figure import Figure
    figures: dict[str, object] = {}
    save = Figure.savefig

    def record(fig: Figure, path: str | pathlib.Path, *args: object, **kwargs: object) -> None:
        path = pathlib.Path(path)
        figures[path.name.removeprefix('.').replace('.partial', '')] = fig
        save(fig, path, *args, **kwargs)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Figure, 'savefig', record)
        yield figures


@pytest.fixture(scope='session')
def record_figures() -> Callable[[], contextlib.AbstractContextManager[dict[str, object]]]:
    """``recording_figures`` (for fixtures of a wider scope than ``saved_figures``)."""
    return recording_figures


@pytest.fixture
def saved_figures() -> Iterator[dict[str, object]]:
    """The figures saved during the test, by file name (``recording_figures``)."""
    with recording_figures() as figures:
        yield figures


def _overlap(a, b, tol: float = 0.5) -> bool:
    """Two display-space boxes share more than ``tol`` pixels in both directions."""
    return (min(a.x1, b.x1) - max(a.x0, b.x0) > tol
            and min(a.y1, b.y1) - max(a.y0, b.y0) > tol)


def assert_legends_clear(fig) -> int:
    """Every legend of ``fig`` (drawn on an Agg canvas) lies above its own axes, inside the
    figure, its entries apart, clear of every axes, title, text and other legend; the number
    of legends."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text
    FigureCanvasAgg(fig).draw()
    renderer = fig.canvas.get_renderer()
    legends = [(ax, ax.get_legend()) for ax in fig.axes if ax.get_legend() is not None]
    texts = [artist for ax in fig.axes for artist in ax.get_children()
             if isinstance(artist, Text) and artist.get_text()] + list(fig.texts)
    for ax, legend in legends:
        box = legend.get_window_extent(renderer)
        where = f'legend of {[t.get_text() for t in legend.get_texts()]}'
        assert box.y0 >= ax.get_window_extent(renderer).y1 - 0.5, f'{where} on the data'
        assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1 + 0.5, f'{where} cut off'
        assert box.y1 <= fig.bbox.y1 + 0.5, f'{where} cut off at the top'
        for other in fig.axes:
            assert not _overlap(box, other.get_window_extent(renderer)), f'{where} on axes'
        for text in texts:
            assert not _overlap(box, text.get_window_extent(renderer)), (
                f'{where} on the text {text.get_text()!r}')
        for _, another in legends:
            if another is not legend:
                assert not _overlap(box, another.get_window_extent(renderer)), (
                    f'{where} on another legend')
        entries = [t.get_window_extent(renderer) for t in legend.get_texts()]
        for a, b in itertools.combinations(entries, 2):
            assert not _overlap(a, b), f'{where}: entries overlap'
    return len(legends)


@pytest.fixture(scope='session')
def legends_clear() -> Callable[[object], int]:
    """``assert_legends_clear``."""
    return assert_legends_clear
