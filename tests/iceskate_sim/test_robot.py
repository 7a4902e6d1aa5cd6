"""Table 1 facts and the geometry of the four support-rooted models (docs/model.md §1, §2).

Expectations are written from the tables of docs/model.md §2 (lengths, masses, damping, centres
of mass), never from numbers the code printed.
"""

import itertools
import math
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import N_COORDINATES, anatomical_map
from oracle.floating_base import FloatingBaseDynamics

SIDES = ('right', 'left')
PIVOTS = ('toe', 'heel')
SUPPORT_KEYS = list(itertools.product(SIDES, PIVOTS))
HIP_X = 0.27 / 2  # hips at x = +-0.135 (right is +x)
SHOULDER_X = 0.20  # s
HEEL_Y, TOE_Y, SOLE_DEPTH = -0.06, 0.20, 0.07  # sole edges relative to the ankle

# Table 1 per anatomical link: (mass [kg], CoM height at zero configuration [m], CoM y [m]),
# the height being the joint height of docs/model.md §2.2 plus the CoM offset of §2.3.
LINK_TABLE = {
    'foot': (1.3, 0.07 - 0.035, 0.07),
    'shank': (3.4, 0.07 + 0.40 / 2, 0.0),
    'thigh': (7.3, 0.47 + 0.38 / 2, 0.0),
    'pelvis': (2.0, 0.85, 0.0),
    'torso_lower': (2.0, 0.85 + 0.05, 0.0),
    'torso_middle': (2.0, 0.95 + 0.05, 0.0),
    'chest': (21.5, 1.05 + 0.205, 0.0),
    'upper_arm': (2.3, 1.46 - 0.155, 0.0),
    'forearm': (1.4, 1.15 - 0.12, 0.0),
    'hand': (0.4, 0.91 - 0.09, 0.0),
    'head': (4.5, 1.46 + 0.12, 0.0),
}
LATERAL = {'foot': HIP_X, 'shank': HIP_X, 'thigh': HIP_X, 'upper_arm': SHOULDER_X,
           'forearm': SHOULDER_X, 'hand': SHOULDER_X}
# Table-2 joint -> link it moves, for a right support foot (docs/model.md §2.1, §2.2).
MOVED_BY_RIGHT_SUPPORT = {
    1: 'right_foot', 2: 'right_shank', 3: 'right_thigh', 4: 'pelvis', 5: 'left_thigh',
    6: 'left_shank', 7: 'left_foot', 8: 'torso_lower', 9: 'torso_middle', 10: 'chest',
    11: 'right_upper_arm', 12: 'right_forearm', 13: 'right_hand', 14: 'left_upper_arm',
    15: 'left_forearm', 16: 'left_hand', 17: 'head'}
# Damping of docs/model.md §2.6, index = Table-2 coordinate [y0, q1..q17].
DAMPING = [0.0, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 0.03, 1.0, 2.0, 0.03, 1.0, 2.0, 0.5]


def _kind(link: str) -> str:
    for prefix in ('right_', 'left_'):
        if link.startswith(prefix):
            return link[len(prefix):]
    return link


def _side_sign(link: str) -> float:
    return 1.0 if link.startswith('right_') else -1.0 if link.startswith('left_') else 0.0


def _moved_by(side: str) -> dict[int, str]:
    """Table-2 joint -> link; with a left support foot the legs swap, the arms do not."""
    swap = {'right': 'left', 'left': 'right'}
    moved = {}
    for i, link in MOVED_BY_RIGHT_SUPPORT.items():
        prefix, _, rest = link.partition('_')
        if side == 'left' and i <= 7 and prefix in swap:
            link = f'{swap[prefix]}_{rest}'
        moved[i] = link
    return moved


def _expected_com(link: str) -> np.ndarray:
    """World CoM of ``link`` at zero configuration (support ankle at y = 0, sole at z = 0)."""
    mass, z, y = LINK_TABLE[_kind(link)]
    del mass
    return np.array([_side_sign(link) * LATERAL.get(_kind(link), 0.0), y, z])


def _placements(support_model, q: np.ndarray) -> dict[str, pin.SE3]:
    model = support_model.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return {name: data.oMf[fid].copy() for name, fid in support_model.frame_ids.items()}


def _all_links() -> list[str]:
    return list(MOVED_BY_RIGHT_SUPPORT.values())


def _assert_same_pose(a: pin.SE3, b: pin.SE3, tol: float, what: str) -> None:
    error = max(np.max(np.abs(a.translation - b.translation)),
                np.max(np.abs(a.rotation - b.rotation)))
    assert error <= tol, f'{what}: poses differ by {error:.3e}\n{a}\n{b}'


# ------------------------------------------------------------------------------------ Table 1
def test_total_mass_is_64_2_kg_in_urdf_and_every_support_model(robot):
    urdf_masses = [float(link.find('inertial/mass').get('value'))
                   for link in ET.parse(robot.urdf_path).getroot().iter('link')
                   if link.find('inertial') is not None]
    assert sum(urdf_masses) == pytest.approx(64.2, abs=1e-9)
    assert robot.total_mass == pytest.approx(64.2, abs=1e-9)
    for key, sm in robot.models.items():
        assert pin.computeTotalMass(sm.model) == pytest.approx(64.2, abs=1e-9), key


def test_table_1_link_masses_in_urdf_mirror_left_and_right(robot):
    root = ET.parse(robot.urdf_path).getroot()
    urdf_mass = {link.get('name'): float(link.find('inertial/mass').get('value'))
                 for link in root.iter('link') if link.find('inertial') is not None}
    assert set(urdf_mass) == set(_all_links())
    for link, mass in urdf_mass.items():
        assert mass == pytest.approx(LINK_TABLE[_kind(link)][0], abs=1e-12), link


@pytest.mark.parametrize(('side', 'pivot'), SUPPORT_KEYS)
def test_each_table_2_joint_moves_the_table_1_link(robot, side, pivot):
    """Joint i of the support model carries link i's mass, and its CoM sits where 2.5 says."""
    sm = robot.support_model(side, pivot)
    model = sm.model
    data = model.createData()
    pin.forwardKinematics(model, data, np.zeros(N_COORDINATES))
    assert model.nq == model.nv == N_COORDINATES
    assert model.inertias[model.getJointId('y0')].mass == 0.0
    for i, link in _moved_by(side).items():
        jid = model.getJointId(f'q{i}')
        inertia = model.inertias[jid]
        assert inertia.mass == pytest.approx(LINK_TABLE[_kind(link)][0], abs=1e-12), (i, link)
        world_com = data.oMi[jid].act(inertia.lever)
        np.testing.assert_allclose(world_com, _expected_com(link), rtol=0, atol=1e-12,
                                   err_msg=f'CoM of link {i} ({link})')


def test_damping_per_table_2_joint_equals_table_1(robot):
    np.testing.assert_array_equal(robot.damping, np.array(DAMPING))
    # and the URDF joints carry the same values (support leg joints mirror the swing leg)
    root = ET.parse(robot.urdf_path).getroot()
    urdf = {j.get('name'): float(j.find('dynamics').get('damping'))
            for j in root.iter('joint') if j.find('dynamics') is not None}
    for side in SIDES:
        for i, name, _sign in anatomical_map(side):
            assert urdf[name] == DAMPING[i], (side, i, name)


@pytest.mark.parametrize(('side', 'pivot'), SUPPORT_KEYS)
def test_standing_height_is_1_70_m(robot, side, pivot, assert_close):
    sm = robot.support_model(side, pivot)
    for y0 in (0.0, 0.37):
        q = np.zeros(N_COORDINATES)
        q[0] = y0
        head = _placements(sm, q)['head_top']
        assert_close(head.translation, [0.0, y0, 1.70], atol=1e-12, what='head top')
    # Table 1 height sum: ankle 0.07 + 0.40 + 0.38 + 0.10 + 0.10 + 0.41 + head 0.24
    assert 0.07 + 0.40 + 0.38 + 0.10 + 0.10 + 0.41 + 0.24 == pytest.approx(1.70)


def test_urdf_head_top_is_1_70_m_above_the_soles(robot):
    model = robot.urdf_model
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    z = {name: data.oMf[model.getFrameId(name)].translation[2]
         for name in ('head_top', 'right_heel', 'left_toe')}
    assert z['head_top'] - z['right_heel'] == pytest.approx(1.70, abs=1e-12)
    assert z['head_top'] - z['left_toe'] == pytest.approx(1.70, abs=1e-12)


@pytest.mark.parametrize(('side', 'pivot'), SUPPORT_KEYS)
def test_whole_body_com_at_zero_configuration(robot, side, pivot, assert_close):
    total = sum(LINK_TABLE[_kind(link)][0] for link in _all_links())
    expected = sum(LINK_TABLE[_kind(link)][0] * _expected_com(link) for link in _all_links())
    expected = expected / total
    assert expected[2] == pytest.approx(0.9455, abs=5e-4)  # the value of docs/model.md §2.5
    model = robot.support_model(side, pivot).model
    com = pin.centerOfMass(model, model.createData(), np.zeros(N_COORDINATES))
    assert_close(com, expected, atol=1e-12, what='whole-body CoM')


# ----------------------------------------------------------------------------- geometry
def test_four_support_models_agree_at_zero_configuration(robot):
    q = np.zeros(N_COORDINATES)
    q[0] = -0.4
    poses = {key: _placements(robot.support_model(*key), q) for key in SUPPORT_KEYS}
    reference = poses[('right', 'toe')]
    for key, placements in poses.items():
        for link in [*_all_links(), 'head_top', 'pelvis_centre']:
            _assert_same_pose(placements[link], reference[link], 1e-12, f'{key} {link}')
            assert np.allclose(placements[link].rotation, np.eye(3), atol=1e-15)
    # and the link frames are the URDF's (shifted so the soles are at z = 0, ankles at y = y0)
    model = robot.urdf_model
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    heel = data.oMf[model.getFrameId('right_heel')].translation
    shift = np.array([0.0, q[0] + HEEL_Y - heel[1], -heel[2]])
    for link in _all_links():
        expected = data.oMf[model.getFrameId(link)].translation + shift
        np.testing.assert_allclose(reference[link].translation, expected, atol=1e-12,
                                   err_msg=link)


@pytest.mark.parametrize('side', SIDES)
def test_pivot_choice_does_not_matter_when_the_sole_is_flat(robot, rng, side):
    toe, heel = robot.support_model(side, 'toe'), robot.support_model(side, 'heel')
    for _ in range(5):
        q = np.zeros(N_COORDINATES)
        q[0] = rng.uniform(-1, 1)
        q[2:] = rng.uniform(-1.0, 1.0, N_COORDINATES - 2)
        a, b = _placements(toe, q), _placements(heel, q)
        assert set(a) == set(b)
        for name in a:
            _assert_same_pose(a[name], b[name], 1e-12, f'{side} {name}')


@pytest.mark.parametrize(('side', 'pivot'), SUPPORT_KEYS)
def test_sole_edge_frames(robot, side, pivot, assert_close):
    sm = robot.support_model(side, pivot)
    x_support = HIP_X if side == 'right' else -HIP_X
    y0 = 0.25
    q = np.zeros(N_COORDINATES)
    q[0] = y0
    p = {k: v.translation for k, v in _placements(sm, q).items()}
    assert_close(p['support_heel'], [x_support, y0 + HEEL_Y, 0.0], atol=1e-12, what='heel')
    assert_close(p['support_toe'], [x_support, y0 + TOE_Y, 0.0], atol=1e-12, what='toe')
    assert_close(p['swing_heel'], [-x_support, y0 + HEEL_Y, 0.0], atol=1e-12, what='sw heel')
    assert_close(p['swing_toe'], [-x_support, y0 + TOE_Y, 0.0], atol=1e-12, what='sw toe')
    assert TOE_Y - HEEL_Y == pytest.approx(0.26)  # Table 1 sole length
    # tipping: the pivot edge stays on the floor, the other edge rises by 0.26 sin|q1|;
    # toe pivot: q1 < 0 lifts the heel; heel pivot: q1 > 0 lifts the toe (docs/model.md §3.4)
    q1 = -0.2 if pivot == 'toe' else 0.2
    q[1] = q1
    tipped = {k: v.translation for k, v in _placements(sm, q).items()}
    fixed, lifted = ('support_toe', 'support_heel') if pivot == 'toe' else (
        'support_heel', 'support_toe')
    assert_close(tipped[fixed], p[fixed], atol=1e-12, what=f'{pivot} pivot edge')
    assert tipped[lifted][2] == pytest.approx(0.26 * math.sin(abs(q1)), abs=1e-12)
    # the ankle turns with the foot as one rigid body about the pivot edge
    pivot_point = p[fixed]
    ankle = p[f'{side}_foot']
    c, s = math.cos(q1), math.sin(q1)
    rel_y, rel_z = ankle[1] - pivot_point[1], ankle[2] - pivot_point[2]
    expected = pivot_point + np.array([0.0, c * rel_y - s * rel_z, s * rel_y + c * rel_z])
    assert_close(tipped[f'{side}_foot'], expected, atol=1e-12, what='support ankle')


def test_positive_pitch_tilts_backward(robot, assert_close):
    """Sign convention of docs/model.md §1.2: +q2 (support ankle) tilts the upright body back."""
    sm = robot.support_model('right', 'toe')
    q = np.zeros(N_COORDINATES)
    q[2] = 0.1
    head = _placements(sm, q)['head_top'].translation
    height = 1.70 - 0.07
    assert_close(head[1:], [-height * math.sin(0.1), 0.07 + height * math.cos(0.1)],
                 atol=1e-12, what='head top after +q2')


@pytest.mark.parametrize('side', SIDES)
def test_knee_flexion_signs(robot, side):
    """+q3 flexes the support knee (URDF knee < 0), -q6 flexes the swing knee (URDF knee < 0)."""
    swing = 'left' if side == 'right' else 'right'
    signs = {i: (name, sign) for i, name, sign in anatomical_map(side)}
    assert signs[3] == (f'{side}_knee_pitch', -1.0)
    assert signs[6] == (f'{swing}_knee_pitch', 1.0)
    assert signs[2] == (f'{side}_ankle_pitch', -1.0)
    assert signs[4] == (f'{side}_hip_pitch', -1.0)
    assert all(sign == 1.0 for i, (_n, sign) in signs.items() if i >= 5)
    sm = robot.support_model(side, 'toe')
    fb = FloatingBaseDynamics(robot)
    contact = ContactState(get_mode(1), side)
    # a flexed knee points forward of the hip-ankle line (human knee): with +q3 the support hip
    # moves behind the support knee, with -q6 the swing ankle moves behind the swing knee
    for i, angle, upper, lower, knee in ((3, 0.3, f'{side}_thigh', f'{side}_shank', side),
                                         (6, -0.3, f'{swing}_foot', f'{swing}_shank', swing)):
        q = np.zeros(N_COORDINATES)
        q[i] = angle
        p = {k: v.translation for k, v in _placements(sm, q).items()}
        assert p[upper][1] < p[lower][1] - 0.1, (i, p[upper], p[lower])
        # the URDF knee reads as flexion (negative) through the floating-base state map
        q_ff, _ = fb.state(contact, q, np.zeros(N_COORDINATES))
        idx = fb.model.joints[fb.model.getJointId(f'{knee}_knee_pitch')].idx_q
        assert q_ff[idx] == pytest.approx(-0.3, abs=1e-15), knee


@pytest.mark.parametrize(('side', 'pivot'), SUPPORT_KEYS)
def test_anatomical_map_reproduces_every_link_pose_and_velocity(robot, rng, side, pivot,
                                                                random_state):
    """The URDF free-flyer at ``FloatingBaseDynamics.state`` matches the support model."""
    fb = FloatingBaseDynamics(robot)
    sm = robot.support_model(side, pivot)
    urdf, urdf_data = fb.model, fb.model.createData()
    data = sm.model.createData()
    for mode_number in (4, 20):  # y0 and q1 active, so every coordinate moves
        contact = ContactState(get_mode(mode_number), side, pivot)
        for _ in range(3):
            q, v = random_state(mode_number, scale=1.0, within_limits=False)
            q_ff, v_ff = fb.state(contact, q, v)
            pin.forwardKinematics(urdf, urdf_data, q_ff, v_ff)
            pin.updateFramePlacements(urdf, urdf_data)
            pin.forwardKinematics(sm.model, data, q, v)
            pin.updateFramePlacements(sm.model, data)
            for link in [*_all_links(), 'head_top']:
                fid = sm.frame_ids[link]
                ufid = urdf.getFrameId(link)
                _assert_same_pose(urdf_data.oMf[ufid], data.oMf[fid], 1e-12, link)
                expected = pin.getFrameVelocity(sm.model, data, fid, pin.LOCAL_WORLD_ALIGNED)
                got = pin.getFrameVelocity(urdf, urdf_data, ufid, pin.LOCAL_WORLD_ALIGNED)
                np.testing.assert_allclose(got.vector, expected.vector, rtol=0, atol=1e-11,
                                           err_msg=f'velocity of {link}')
            for role, urdf_side in (('support', side),
                                    ('swing', 'left' if side == 'right' else 'right')):
                for edge in ('heel', 'toe'):
                    _assert_same_pose(urdf_data.oMf[urdf.getFrameId(f'{urdf_side}_{edge}')],
                                      data.oMf[sm.frame_ids[f'{role}_{edge}']], 1e-12,
                                      f'{role} {edge}')


def test_unknown_side_or_pivot_is_rejected(robot):
    with pytest.raises(SimulationError, match="'centre'"):
        anatomical_map('centre')
    with pytest.raises(SimulationError, match="'middle'"):
        robot.support_model('right', 'middle')
    with pytest.raises(SimulationError, match="'up'"):
        robot.support_model('up', 'toe')


# ------------------------------------------------------------------------------------ the body
def _urdf_without_visuals(robot, tmp_path) -> str:
    """The shipped URDF with every <visual> element taken out (written under ``tmp_path``)."""
    root = ET.parse(robot.urdf_path).getroot()
    for link in root.findall('link'):
        for visual in link.findall('visual'):
            link.remove(visual)
    path = tmp_path / 'no_visuals.urdf'
    ET.ElementTree(root).write(path)
    return str(path)


def test_every_link_with_mass_has_a_body_coloured_by_side(robot):
    model = robot.urdf_model
    geometry = pin.buildGeomFromUrdf(model, str(robot.urdf_path), pin.GeometryType.VISUAL)
    colours: dict[str, set[tuple]] = {}
    for item in geometry.geometryObjects:
        link = model.frames[item.parentFrame].name
        colours.setdefault(link, set()).add(tuple(np.round(item.meshColor, 3)))
    assert set(colours) == set(_all_links())
    for link in _all_links():
        if link.startswith('right_'):
            mirror = 'left_' + link[len('right_'):]
            assert not colours[link] & colours[mirror] - {(0.12, 0.12, 0.14, 1.0)}, link


def test_the_sole_drawn_is_the_contact_sole(robot):
    """The dark box of each foot spans heel to toe edge (0.26 m), 0.10 m wide, its underside
    at the sole edges' height."""
    geometry = pin.buildGeomFromUrdf(robot.urdf_model, str(robot.urdf_path),
                                     pin.GeometryType.VISUAL)
    for side in SIDES:
        soles = [g for g in geometry.geometryObjects
                 if robot.urdf_model.frames[g.parentFrame].name == f'{side}_foot'
                 and isinstance(g.geometry, pin.hppfcl.Box if hasattr(pin, 'hppfcl')
                                else type(g.geometry)) and g.meshColor[0] < 0.2]
        assert len(soles) == 1
        half = soles[0].geometry.halfSide
        centre = soles[0].placement.translation
        assert 2 * half[0] == pytest.approx(0.10)
        assert centre[1] - half[1] == pytest.approx(HEEL_Y)
        assert centre[1] + half[1] == pytest.approx(TOE_Y)
        assert centre[2] - half[2] == pytest.approx(-SOLE_DEPTH)


def test_the_body_leaves_the_dynamics_bit_identical(robot, rng, tmp_path):
    """Mass matrix and bias terms of the URDF model and of every support-rooted model equal,
    bit for bit, those built from the same URDF without its <visual> elements."""
    from iceskate_sim.model.robot import load_robot
    bare = load_robot(_urdf_without_visuals(robot, tmp_path))
    pairs = [(robot.urdf_model, bare.urdf_model)]
    pairs += [(robot.models[key].model, bare.models[key].model) for key in SUPPORT_KEYS]
    for shipped, reference in pairs:
        data, reference_data = shipped.createData(), reference.createData()
        for _ in range(5):
            q = pin.randomConfiguration(shipped, -np.ones(shipped.nq), np.ones(shipped.nq))
            v = rng.normal(size=shipped.nv)
            np.testing.assert_array_equal(pin.crba(shipped, data, q),
                                          pin.crba(reference, reference_data, q))
            np.testing.assert_array_equal(pin.nonLinearEffects(shipped, data, q, v),
                                          pin.nonLinearEffects(reference, reference_data, q, v))
