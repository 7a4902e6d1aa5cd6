"""recording.messages: the bytes of every recorded topic's messages of a native block, each
decoded by rosbags and checked field by field against the block's columns, the gait modes'
definitions and the session's event log."""

from dataclasses import replace
import pathlib
from typing import Any, NamedTuple

import numpy as np
import pytest

from iceskate_bringup.scene import load_scene
from iceskate_native.sample import SAMPLE_COLUMNS
from iceskate_sim.model.modes import MODES, MULTIPLIER_NAMES
from iceskate_sim.model.robot import COORDINATE_NAMES, SOLE_HEEL_Y, SOLE_TOE_Y, load_robot
from iceskate_sim.model.stamps import seconds_to_ns
from iceskate_sim.recording.bag_types import PASSIVE, make_typestore
from iceskate_sim.recording.messages import (
    RECORDED_TOPICS,
    TOPICS,
    Events,
    SampleMessages,
)

#: a fast-stepping skate gait (test data): many events in a short window
FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'
PERIODS = 600


class Run(NamedTuple):
    """One native block of a short run, the session's event log and the robot."""

    block: dict
    events: list
    robot: Any


@pytest.fixture(scope='module')
def run(native_blocks) -> Run:
    scene = replace(load_scene(FAST_SKATE), duration=PERIODS * 1e-3, record_bag=False)
    (block,), events, session = native_blocks(scene, PERIODS)
    return Run(block, events, session.robot)


@pytest.fixture(scope='module')
def typestore():
    return make_typestore()


@pytest.fixture(scope='module')
def links(run) -> list[tuple[str, str]]:
    """The /tf frame pairs."""
    return run.robot.tf_frames


def _messages(typestore, links, block, events) -> dict[str, list]:
    encoded = SampleMessages(typestore, links).encode(block, Events.of(block['last_event'],
                                                                      events))
    assert list(encoded) == list(RECORDED_TOPICS)
    return {topic: [typestore.deserialize_cdr(data, TOPICS[topic]) for data in rows]
            for topic, rows in encoded.items()}


def _stamp(t: float) -> tuple[int, int]:
    return divmod(seconds_to_ns(float(t)), 1_000_000_000)


def _equal(a, b) -> bool:
    return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float), equal_nan=True)


def _check(block: dict, events: list, messages: dict[str, list], links: list) -> None:
    """Every field of every message of ``block`` against its columns."""
    names = list(COORDINATE_NAMES)
    rows = len(block['t'])
    assert all(len(messages[topic]) == rows for topic in RECORDED_TOPICS)
    tf_rows = block['tf'].reshape(rows, len(links), 7)
    for k in range(rows):
        stamp = _stamp(block['t'][k])
        mode = MODES[int(block['mode'][k])]
        acting = [i for i in range(len(block['sources'])) if int(block['present'][k]) >> i & 1]

        clock = messages['/clock'][k]
        assert (clock.clock.sec, clock.clock.nanosec) == stamp

        js = messages['/joint_states'][k]
        assert (js.header.stamp.sec, js.header.stamp.nanosec) == stamp
        assert js.header.frame_id == '' and list(js.name) == names
        assert _equal(js.position, block['q'][k]) and _equal(js.velocity, block['v'][k])
        total = np.zeros(18)
        for i in acting:
            total = total + block['efforts'][i][k]
        assert _equal(js.effort, total)

        pose = messages['/head_pose'][k]
        assert (pose.header.stamp.sec, pose.header.stamp.nanosec) == stamp
        assert pose.header.frame_id == 'world'
        p, o = pose.pose.position, pose.pose.orientation
        assert _equal([p.x, p.y, p.z], block['head_position'][k])
        assert _equal([o.x, o.y, o.z, o.w], block['head_orientation'][k])

        gs = messages['/gait_state'][k]
        assert (gs.header.stamp.sec, gs.header.stamp.nanosec) == stamp
        assert gs.mode == mode.number and gs.support_side == block['side'][k]
        assert gs.pivot == block['pivot'][k]
        assert gs.step_index == block['step_index'][k]
        assert (gs.y0_active, gs.q1_active) == (mode.y0_active, mode.q1_active)
        assert list(gs.multiplier_names) == list(mode.multipliers)
        assert _equal(gs.multipliers, [block['multipliers'][k, MULTIPLIER_NAMES.index(n)]
                                       for n in mode.multipliers])
        assert gs.support_normal_force == block['support_normal'][k]
        assert gs.support_friction_force == block['support_friction'][k]
        cop, y0 = float(block['zmp_y'][k]), float(block['q'][k, 0])
        assert gs.zmp.x == 0.0 and gs.zmp.z == 0.0
        assert _equal(gs.zmp.y, cop if np.isfinite(cop) else np.nan)
        assert gs.zmp_inside_support == (np.isfinite(cop) and not mode.q1_active
                                         and y0 + SOLE_HEEL_Y <= cop <= y0 + SOLE_TOE_Y)
        assert gs.swing_clearance == block['swing_clearance'][k]
        index = int(block['last_event'][k])
        last = events[index] if index >= 0 else None
        assert gs.last_transition_cause == (last.cause if last else '')
        assert (gs.last_transition_stamp.sec, gs.last_transition_stamp.nanosec) == (
            _stamp(last.t) if last else (0, 0))
        assert (gs.support_exchange_stamp.sec, gs.support_exchange_stamp.nanosec) == _stamp(
            block['t_exchange'][k])
        touchdown = float(block['t_touchdown'][k])
        assert gs.touched_down == np.isfinite(touchdown)
        assert (gs.touchdown_stamp.sec, gs.touchdown_stamp.nanosec) == (
            _stamp(touchdown) if np.isfinite(touchdown) else (0, 0))
        assert _equal(gs.heel_anchor_y, block['heel_anchor_y'][k])
        assert _equal(gs.position, block['q'][k]) and _equal(gs.velocity, block['v'][k])

        jd = messages['/joint_dynamics'][k]
        assert (jd.header.stamp.sec, jd.header.stamp.nanosec) == stamp
        assert list(jd.name) == names
        assert np.flatnonzero(jd.active).tolist() == sorted(np.asarray(mode.active).tolist())
        assert _equal(jd.acceleration, block['qdd'][k])
        assert list(jd.source_names) == [*(block['sources'][i] for i in acting), PASSIVE]
        assert _equal(jd.source_efforts.reshape(-1, 18),
                      [*(block['efforts'][i][k] for i in acting), block['passive'][k]])

        tf = messages['/tf'][k]
        assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == links
        for t, row in zip(tf.transforms, tf_rows[k], strict=True):
            assert (t.header.stamp.sec, t.header.stamp.nanosec) == stamp
            x, r = t.transform.translation, t.transform.rotation
            assert _equal([x.x, x.y, x.z, r.x, r.y, r.z, r.w], row)


def test_the_run_covers_the_cases(run):
    """What the fields depend on varies over the block: gait modes with and without
    multipliers, both sides and pivots, heel strikes, transitions of several causes."""
    b = run.block
    modes = set(b['mode'].tolist())
    assert len(modes) >= 4 and any(MODES[m].multipliers for m in modes)
    assert any(not MODES[m].multipliers for m in modes)
    assert set(b['side'].tolist()) == {0, 1} and len(set(b['pivot'].tolist())) >= 2
    assert np.isfinite(b['t_touchdown']).any() and np.isnan(b['t_touchdown']).any()
    assert len({run.events[i].cause for i in b['last_event'].tolist() if i >= 0}) >= 4
    assert len(set(b['t_exchange'].tolist())) >= 2
    assert len(b['sources']) >= 3 and PASSIVE not in b['sources']


def test_every_field_is_the_blocks(run, typestore, links):
    _check(run.block, run.events, _messages(typestore, links, run.block, run.events), links)


def test_the_latest_transition_is_the_last_one_logged_by_then(run):
    """Cross-check of the block's ``last_event``: the last transition of the log at or before
    the sample's time (as the oracle's ``reference_samples`` finds it)."""
    for t, index in zip(run.block['t'].tolist(), run.block['last_event'].tolist(), strict=True):
        expected = max((i for i, e in enumerate(run.events) if e.t <= t), default=-1)
        assert index == expected, t


def _rows(block: dict, selected) -> dict:
    out = {key: value[selected] if isinstance(value, np.ndarray) else value
           for key, value in block.items()}
    out['efforts'] = [effort[selected] for effort in block['efforts']]
    return out


def _synthetic(block: dict) -> dict:
    """Every 7th row of the block, with unknown CoPs (NaN), touchdown times NaN or finite,
    sources that did not act (efforts 0 there) and rows before any transition."""
    out = _rows(block, np.arange(0, len(block['t']), 7))
    out = {key: value.copy() if isinstance(value, np.ndarray) else value
           for key, value in out.items()}
    out['efforts'] = [e.copy() for e in out['efforts']]
    m = len(out['t'])
    out['zmp_y'][0:3] = np.nan  # no support force (the loop's CoP is NaN then, never inf)
    out['zmp_y'][5::5] = np.nan
    out['t_touchdown'][0::3] = np.nan
    out['t_touchdown'][1::3] = out['t'][1::3] * 0.5
    out['last_event'][:4] = -1
    # the stamps of the changed times, as the loop would have given them
    out['stamps_ns'][:, 2] = [0 if np.isnan(t) else seconds_to_ns(t)
                              for t in out['t_touchdown'].tolist()]
    out['stamps_ns'][:4, 3] = 0
    full = (1 << len(out['sources'])) - 1
    present = np.full(m, full, dtype=out['present'].dtype)
    for k in range(m):
        if k % 4:
            dropped = k % len(out['sources'])
            present[k] &= ~np.uint64(1 << dropped)
            out['efforts'][dropped][k] = 0.0
    out['present'] = present
    # the columns the loop derives from those changed, as it would have given them
    out['effort_total'] = np.sum(out['efforts'], axis=0)
    out['zmp_inside_support'][np.isnan(out['zmp_y'])] = 0
    out['touched_down'] = (~np.isnan(out['t_touchdown'])).astype(np.uint8)
    return out


def test_non_finite_values_and_sources_that_did_not_act(run, typestore, links):
    block = _synthetic(run.block)
    assert len(set(block['present'].tolist())) >= 3
    messages = _messages(typestore, links, block, run.events)
    _check(block, run.events, messages, links)
    zmp = [gs.zmp.y for gs in messages['/gait_state']]
    assert np.isnan(zmp[0:3]).all() and not any(gs.zmp_inside_support
                                                 for gs in messages['/gait_state'][0:3])
    assert [gs.touched_down for gs in messages['/gait_state'][:2]] == [False, True]
    assert messages['/gait_state'][1].touchdown_stamp.nanosec > 0
    assert messages['/gait_state'][0].last_transition_cause == ''


def _encode_rows_one_by_one(typestore, links, block, events) -> dict[str, list[bytes]]:
    messages = SampleMessages(typestore, links)
    out = {topic: [] for topic in RECORDED_TOPICS}
    for k in range(len(block['t'])):
        row = _rows(block, slice(k, k + 1))
        for topic, data in messages.encode(row, Events.of(row['last_event'], events)).items():
            out[topic] += data
    return out


@pytest.mark.parametrize('synthetic', [False, True], ids=['run', 'synthetic'])
def test_a_block_encodes_as_its_rows_one_by_one(run, typestore, links, synthetic):
    block = _synthetic(run.block) if synthetic else _rows(run.block, slice(0, None, 3))
    at_once = SampleMessages(typestore, links).encode(
        block, Events.of(block['last_event'], run.events))
    assert at_once == _encode_rows_one_by_one(typestore, links, block, run.events)
    assert all(isinstance(data, bytes) for rows in at_once.values() for data in rows)


def test_the_loops_stamps_round_as_seconds_to_ns(run):
    """The native loop's stamps_ns against Python's rounding of the times they stamp (whole
    nanoseconds, ties to even): t, the support exchange, the heel strike (0 before it) and
    the latest transition (0 before any)."""
    b, events = run.block, run.events
    touchdown = [0 if np.isnan(t) else seconds_to_ns(t) for t in b['t_touchdown'].tolist()]
    last = [0 if i < 0 else seconds_to_ns(events[i].t) for i in b['last_event'].tolist()]
    assert b['stamps_ns'].dtype == np.int64
    assert b['stamps_ns'].tolist() == [
        [seconds_to_ns(t), seconds_to_ns(x), d, e] for t, x, d, e in zip(
            b['t'].tolist(), b['t_exchange'].tolist(), touchdown, last, strict=True)]
    assert 0 < min(touchdown[k] for k in range(len(touchdown)) if touchdown[k])
    assert any(last) and not all(last)


def test_events_of_a_block(run):
    events = run.events
    mixed = np.array([-1, 2, 2, 5, -1, 3])
    got = Events.of(mixed, events)
    assert [got.causes[c] for c in got.cause.tolist()] == [
        '' if i < 0 else events[i].cause for i in mixed.tolist()]
    for same in (np.array([4, 4, 4]), np.array([4]), np.array([-1, -1])):
        got = Events.of(same, events)
        i = int(same[0])
        assert [got.causes[c] for c in got.cause.tolist()] == [
            events[i].cause if i >= 0 else ''] * len(same)


def test_the_robot_description(typestore, links):
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    data = SampleMessages(typestore, links).description(urdf)
    assert typestore.deserialize_cdr(data, TOPICS['/robot_description']).data == urdf
    assert data == bytes(typestore.serialize_cdr(
        typestore.types['std_msgs/msg/String'](data=urdf), 'std_msgs/msg/String'))


def test_every_routed_column_is_in_its_message_field(run, typestore, links) -> None:
    """The sample table's routes, read generically: each field holds its column's values."""
    messages = _messages(typestore, links, run.block, run.events)
    routes = [(column, route) for column in SAMPLE_COLUMNS.values() for route in column.routes]
    assert {route.topic for _, route in routes} == {'/joint_states', '/gait_state',
                                                   '/joint_dynamics', '/head_pose'}
    for k in range(0, len(run.block['t']), 7):
        for column, route in routes:
            value = messages[route.topic][k]
            for part in route.path.split('.'):
                value = getattr(value, part)
            if route.axes:
                value = [getattr(value, axis) for axis in route.axes]
            assert _equal(value, run.block[column.name][k]), (column.name, route, k)
