"""The humanoid of the paper's Table 1 as Pinocchio models rooted at the support foot:
``load_robot`` -> ``Robot`` with a ``SupportModel`` per side and pivot, from the pelvis-rooted
URDF; coordinates ``[y0, q1, ..., q17]``, SI units. See docs/model.md §1.3 and §2.7.
"""

from __future__ import annotations

from dataclasses import dataclass
import functools
import pathlib

import numpy as np
import pinocchio as pin

from iceskate_sim.errors import SimulationError
from iceskate_sim.installed import share_path

N_COORDINATES = 18
COORDINATE_NAMES: tuple[str, ...] = ('y0',) + tuple(f'q{i}' for i in range(1, 18))
Y0 = 0
Q1 = 1
SIDES = ('right', 'left')  # support side: a = 0 right, a = 1 left (paper's eq. 10)
PIVOTS = ('toe', 'heel')
SOLE_HEEL_Y = -0.06  # m, heel edge relative to the ankle along the foot (docs/model.md §2.4)
SOLE_TOE_Y = 0.20  # m, toe edge relative to the ankle
SOLE_Z = -0.07  # m, sole plane below the ankle
PIVOT_Y = {'toe': SOLE_TOE_Y, 'heel': SOLE_HEEL_Y}
GRAVITY = 9.81  # m/s^2

UPPER_BODY = {  # Table-2 joint -> (URDF joint, URDF child link)
    8: ('torso_yaw', 'torso_lower'),
    9: ('lumbar_pitch', 'torso_middle'),
    10: ('thorax_pitch', 'chest'),
    11: ('right_shoulder_pitch', 'right_upper_arm'),
    12: ('right_elbow_pitch', 'right_forearm'),
    13: ('right_wrist_pitch', 'right_hand'),
    14: ('left_shoulder_pitch', 'left_upper_arm'),
    15: ('left_elbow_pitch', 'left_forearm'),
    16: ('left_wrist_pitch', 'left_hand'),
    17: ('neck_pitch', 'head'),
}
UPPER_BODY_PARENT = {8: 4, 9: 8, 10: 9, 11: 10, 12: 11, 13: 12, 14: 10, 15: 14, 16: 15, 17: 10}
LINK_NAMES = ('pelvis', 'torso_lower', 'torso_middle', 'chest', 'head', 'right_thigh',
              'right_shank', 'right_foot', 'left_thigh', 'left_shank', 'left_foot',
              'right_upper_arm', 'right_forearm', 'right_hand', 'left_upper_arm',
              'left_forearm', 'left_hand')
# Soft joint stops of docs/model.md §2.6 in Table-2 coordinates [rad]: (lower, upper).
# The support knee (q3) and swing knee (q6) only flex, with opposite signs.
JOINT_LIMITS = {3: (0.0, 2.5), 6: (-2.5, 0.0), 8: (-1.0, 1.0), 9: (-0.8, 0.8),
                10: (-0.8, 0.8), 12: (0.0, 2.5), 13: (-1.0, 1.0), 15: (0.0, 2.5),
                16: (-1.0, 1.0), 17: (-0.8, 0.8)}


def anatomical_map(side: str) -> list[tuple[int, str, float]]:
    """(Table-2 joint, URDF joint, sign) with ``q_urdf = sign * q_i`` for joints 2..17.

    The support leg is traversed from foot to hip in Table 2 and from hip to foot in the URDF,
    so its three joints change sign; q1 (the floor pivot) has no URDF joint.
    """
    if side not in SIDES:
        raise SimulationError(f'unknown support side {side!r}; expected one of {SIDES}')
    swing = _other(side)
    mapping = [(2, f'{side}_ankle_pitch', -1.0), (3, f'{side}_knee_pitch', -1.0),
               (4, f'{side}_hip_pitch', -1.0), (5, f'{swing}_hip_pitch', 1.0),
               (6, f'{swing}_knee_pitch', 1.0), (7, f'{swing}_ankle_pitch', 1.0)]
    mapping += [(i, urdf_joint, 1.0) for i, (urdf_joint, _link) in UPPER_BODY.items()]
    return mapping


@dataclass(frozen=True)
class _Link:
    """A rigid link in world coordinates at the zero configuration."""

    name: str
    mass: float  # kg
    com: np.ndarray  # m, world
    inertia: np.ndarray  # kg m^2 about the CoM, world-aligned (3x3)
    origin: np.ndarray  # m, world position of the URDF link frame


@dataclass(frozen=True)
class SupportModel:
    """A Pinocchio model of the robot rooted at one support foot with one pivot edge.

    ``model`` has 18 one-dof joints in Table-2 order (nq = nv = 18). Frames: ``head_top``,
    ``swing_heel``, ``swing_toe``, ``support_heel``, ``support_toe`` (also by their URDF link
    names, ``right_heel``, ...), ``pelvis_centre`` and one body frame per anatomical link
    (``right_shank``, ...), at the URDF link origin, so that the same physical frame exists in
    every support model.
    """

    side: str
    pivot: str
    model: pin.Model
    frame_ids: dict[str, int]

    def new_data(self) -> pin.Data:
        """Return a fresh Pinocchio data object for this model."""
        return self.model.createData()


@dataclass(frozen=True, eq=False)
class Robot:
    """The humanoid: the four support-rooted models and the per-coordinate constants (equal
    and hashed by identity: a key of the caches made from it)."""

    urdf_path: pathlib.Path
    urdf_model: pin.Model
    models: dict[tuple[str, str], SupportModel]
    damping: np.ndarray  # N m s/rad per Table-2 coordinate (y0: 0), shape (18,)
    effort_limit: np.ndarray  # N m (N for y0) per Table-2 coordinate, shape (18,)
    total_mass: float  # kg

    @property
    def tf_frames(self) -> list[tuple[str, str]]:
        """The (parent, child) frames of /tf in robot_state_publisher's layout: ``world`` -> the
        URDF's root link (the link on its universe frame), then parent link -> child link of
        each URDF joint (the fixed ones too), in the URDF model's frame order."""
        frames = self.urdf_model.frames
        child_of = {f.parentFrame: f.name for f in frames if f.type == pin.FrameType.BODY}
        joints = (pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT)
        return [('world', child_of[0]), *((frames[f.parentFrame].name, child_of[k])
                                          for k, f in enumerate(frames)
                                          if k and f.type in joints)]

    def support_model(self, side: str, pivot: str) -> SupportModel:
        """Return the model rooted at the ``side`` foot pivoting about its ``pivot`` edge."""
        try:
            return self.models[(side, pivot)]
        except KeyError:
            raise SimulationError(
                f'unknown support side/pivot {side!r}/{pivot!r}; '
                f'expected side in {SIDES} and pivot in {PIVOTS}') from None


def _other(side: str) -> str:
    return 'left' if side == 'right' else 'right'


def _urdf_links(urdf_model: pin.Model) -> tuple[dict[str, _Link], dict[str, np.ndarray]]:
    """World geometry of every link and joint at the zero configuration, soles at z = 0."""
    data = urdf_model.createData()
    q0 = pin.neutral(urdf_model)
    pin.forwardKinematics(urdf_model, data, q0)
    pin.updateFramePlacements(urdf_model, data)
    heel = data.oMf[urdf_model.getFrameId('right_heel')].translation
    shift = np.array([0.0, -heel[1] + SOLE_HEEL_Y, -heel[2]])  # right ankle at y = 0, sole z = 0
    joints = {urdf_model.names[j]: data.oMi[j].translation + shift
              for j in range(1, urdf_model.njoints)}
    links = {}
    for name in LINK_NAMES:
        fid = urdf_model.getFrameId(name)
        frame = urdf_model.frames[fid]
        jid = frame.parentJoint
        origin = data.oMf[fid].translation + shift
        if jid == 0:  # the pelvis: inertia stored on the universe, placed at the root link
            inertia = urdf_model.inertias[0] if frame.inertia.mass == 0 else frame.inertia
        else:
            inertia = urdf_model.inertias[jid]
        if not np.allclose(data.oMf[fid].rotation, np.eye(3)):
            raise SimulationError(f'URDF link {name} is not world-aligned at zero configuration')
        com = data.oMi[jid].translation + shift + inertia.lever
        links[name] = _Link(name, float(inertia.mass), com, inertia.inertia.copy(), origin)
    return links, joints


def _build_support_model(urdf_model: pin.Model, links: dict[str, _Link],
                         joints: dict[str, np.ndarray], side: str, pivot: str) -> SupportModel:
    """Rebuild the tree rooted at the ``side`` foot, with q1 about its ``pivot`` edge."""
    swing = _other(side)
    ankle = joints[f'{side}_ankle_pitch']
    pivot_point = np.array([ankle[0], PIVOT_Y[pivot], 0.0])
    # Table-2 joint -> (parent Table-2 joint, world location, axis, link moved)
    layout = {
        1: (0, pivot_point, 'x', f'{side}_foot'),
        2: (1, ankle, 'x', f'{side}_shank'),
        3: (2, joints[f'{side}_knee_pitch'], 'x', f'{side}_thigh'),
        4: (3, joints[f'{side}_hip_pitch'], 'x', 'pelvis'),
        5: (4, joints[f'{swing}_hip_pitch'], 'x', f'{swing}_thigh'),
        6: (5, joints[f'{swing}_knee_pitch'], 'x', f'{swing}_shank'),
        7: (6, joints[f'{swing}_ankle_pitch'], 'x', f'{swing}_foot'),
    }
    for i, (urdf_joint, link) in UPPER_BODY.items():
        axis = 'z' if i == 8 else 'x'
        layout[i] = (UPPER_BODY_PARENT[i], joints[urdf_joint], axis, link)

    model = pin.Model()
    model.name = f'iceskate_{side}_support_{pivot}_pivot'
    model.gravity = pin.Motion(np.array([0.0, 0.0, -GRAVITY, 0.0, 0.0, 0.0]))
    base = np.array([ankle[0], 0.0, 0.0])  # y0 = world y of the support ankle when flat
    pin_ids = {0: model.addJoint(0, pin.JointModelPY(), pin.SE3(np.eye(3), base), 'y0')}
    location = {0: base}
    for i in range(1, 18):
        parent, where, axis, link_name = layout[i]
        joint_model = pin.JointModelRZ() if axis == 'z' else pin.JointModelRX()
        placement = pin.SE3(np.eye(3), where - location[parent])
        pin_ids[i] = model.addJoint(pin_ids[parent], joint_model, placement, f'q{i}')
        location[i] = where
        link = links[link_name]
        model.appendBodyToJoint(pin_ids[i], pin.Inertia(link.mass, link.com - where,
                                                        link.inertia), pin.SE3.Identity())
    moved_by = {layout[i][3]: i for i in range(1, 18)}

    def add_frame(name: str, joint: int, world: np.ndarray) -> None:
        placement = pin.SE3(np.eye(3), world - location[joint])
        model.addFrame(pin.Frame(name, pin_ids[joint], placement, pin.FrameType.OP_FRAME))

    for name, link in links.items():
        add_frame(name, moved_by[name], link.origin)
    add_frame('pelvis_centre', 4, links['pelvis'].com)
    head = joints['neck_pitch']
    add_frame('head_top', 17, head + np.array([0.0, 0.0, 0.24]))
    swing_ankle = joints[f'{swing}_ankle_pitch']
    for role, foot, joint, ankle_at in (('swing', swing, 7, swing_ankle),
                                        ('support', side, 1, ankle)):
        for edge, y in (('heel', SOLE_HEEL_Y), ('toe', SOLE_TOE_Y)):
            for name in (f'{role}_{edge}', f'{foot}_{edge}'):  # the URDF's sole link too
                add_frame(name, joint, ankle_at + np.array([0.0, y, SOLE_Z]))
    frame_names = ['head_top', 'swing_heel', 'swing_toe', 'support_heel', 'support_toe',
                   *(f'{foot}_{edge}' for foot in SIDES for edge in PIVOTS),
                   'pelvis_centre', *links]
    frame_ids = {name: model.getFrameId(name) for name in frame_names}
    return SupportModel(side, pivot, model, frame_ids)


def _per_coordinate(joint_values: np.ndarray, urdf_model: pin.Model, side: str) -> np.ndarray:
    """A per-joint URDF value (e.g. ``urdf_model.damping``, indexed by velocity) per Table-2
    coordinate of the ``side`` support models; q1, the support foot on its edge, takes its
    ankle's; y0 (no URDF joint): 0."""
    out = np.zeros(N_COORDINATES)
    for i, urdf_joint, _sign in anatomical_map(side):
        out[i] = float(joint_values[urdf_model.joints[urdf_model.getJointId(urdf_joint)].idx_v])
    out[1] = out[2]
    return out


def _damping(urdf_model: pin.Model, side: str) -> np.ndarray:
    """Table 1 damping per Table-2 coordinate, read from the URDF joints (y0: 0)."""
    return _per_coordinate(urdf_model.damping, urdf_model, side)


def _effort_limit(urdf_model: pin.Model, side: str) -> np.ndarray:
    """The URDF joints' effort limits per Table-2 coordinate [N m]; y0 (no URDF joint) takes
    the largest of them [N]."""
    limit = _per_coordinate(urdf_model.effortLimit, urdf_model, side)
    limit[0] = limit[1:].max()
    return limit


@functools.lru_cache(maxsize=4)
def load_robot(urdf_path: str | None = None) -> Robot:
    """Load the URDF (default: the one the package installs, ``share/iceskate_sim/urdf``) and
    prepare the four support-rooted models (cached per path)."""
    path = (pathlib.Path(urdf_path) if urdf_path
            else share_path('iceskate_sim', 'urdf', 'iceskate_humanoid.urdf'))
    try:
        urdf_model = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as exc:
        raise SimulationError(f'cannot read URDF {path}: {exc}') from exc
    links, joints = _urdf_links(urdf_model)
    models = {(side, pivot): _build_support_model(urdf_model, links, joints, side, pivot)
              for side in SIDES for pivot in PIVOTS}
    damping, effort_limit = _damping(urdf_model, 'right'), _effort_limit(urdf_model, 'right')
    if not np.array_equal(damping, _damping(urdf_model, 'left')):
        raise SimulationError('URDF leg damping differs between sides; Table 2 needs it equal')
    if not np.array_equal(effort_limit, _effort_limit(urdf_model, 'left')):
        raise SimulationError('URDF leg effort limits differ between sides; Table 2 needs them '
                              'equal')
    total_mass = float(sum(link.mass for link in links.values()))
    return Robot(path, urdf_model, models, damping, effort_limit, total_mass)
