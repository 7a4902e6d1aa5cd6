"""The gait-manager parameters (docs/model.md §11): a frozen dataclass per source block,
``GaitManagerParameters`` with all of them and the enabled sources, and the tuples of choices
(``SOURCES``, ...), from which the C++ structs and enums are generated at build time.
See docs/architecture.md, 'One parameter schema'.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Self

from gait_manager.errors import GaitManagerError
from iceskate_native.parameters import block, checked, from_mapping, setting
from iceskate_sim.model.stance import StanceSchedule

#: The torque sources, in the order they are computed, sent and summed.
SOURCES = ('posture', 'feedforward', 'weight_transfer', 'heel', 'arm_assist', 'yaw')
#: The posture stabiliser's reference postures.
POSTURE_REFERENCES = ('moving', 'standing', 'balance')
#: The weight-transfer rules for the desired front-heel force f_des.
WEIGHT_RULES = ('ramp', 'com')
#: The readings of eq. (10)'s phase Phi (docs/model.md §11.8).
PHASE_READINGS = ('A', 'B', 'B_clipped')


class _Block:
    """What every gait-manager parameter class does: check and normalise its fields (each a
    ``setting``: description, unit, range) when built, and build from a mapping; errors are
    GaitManagerError naming the (dotted) key."""

    _prefix = ''
    __post_init__ = checked(GaitManagerError)

    def __init_subclass__(cls, prefix: str = '', **kwargs: Any) -> None:
        """``prefix``: the block's name with a dot ('posture.'), '' for the top level."""
        super().__init_subclass__(**kwargs)
        cls._prefix = prefix

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Self:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, cls._prefix)


@dataclass(frozen=True)
class PostureParameters(_Block, prefix='posture.'):
    """Parameters of the posture stabiliser and its stance reference (docs/model.md, posture
    stabiliser)."""

    reference: str = setting(
        'moving', "reference posture: 'moving' stance, fixed 'standing' posture, or 'balance' "
        '(the walking stabiliser of the balance block; only the yaw spring of this block is '
        'used then)', choices=POSTURE_REFERENCES)
    joints: tuple[int, ...] = setting(
        (2, 3, 4, 9, 10), 'joints driven by the PD (stance 2, 3, 4; torso 9, 10; not the neck)',
        low=2, high=17, distinct=True)
    stiffness: float = setting(800.0, 'K_q of the PD (400 also works, 200 is too weak)',
                               unit='N m/rad', low=0.0)
    damping: float = setting(16.0, 'B_q of the PD', unit='N m s/rad', low=0.0)
    gravity_compensation: bool = setting(True, 'add the gravity torque g(q) on gravity_joints')
    gravity_joints: tuple[int, ...] = setting(
        (2, 3, 4, 9, 10), 'joints that get g(q) (stance and torso; never the swing leg in the '
        'air: it throws the leg up)', low=2, high=17, distinct=True)
    yaw_stiffness: float = setting(20.0, 'K_8 of the torso-yaw centring spring', unit='N m/rad',
                                   low=0.0)
    yaw_damping: float = setting(2.0, 'B_8 of the torso-yaw centring spring', unit='N m s/rad',
                                 low=0.0)
    null_space: bool = setting(False, 'project the PD into the null space of the head Jacobian '
                               'J_H over the driven joints')
    bend: float = setting(0.05, 'knee bend a of the bent-knee standing posture', unit='rad',
                          low=0.0, high=0.5)
    pelvis_pitch: float = setting(0.0, 'pelvis pitch phi_4 = q1 + q2 + q3 + q4 kept by the '
                                  "'moving' reference", unit='rad', low=-0.8, high=0.8)
    shift_y1: float = setting(0.10, 'forward hip shift dy1 after the support exchange',
                              unit='m', low=-0.4, high=0.4)
    shift_z1: float = setting(0.03, 'downward hip shift dz1 after the support exchange',
                              unit='m', low=-0.1, high=0.3)
    shift_time1: float = setting(0.6, 'duration T1 of the first shift', unit='s', low=0.0)
    shift_y2: float = setting(0.10, 'further forward hip shift dy2 after the heel strike',
                              unit='m', low=-0.4, high=0.4)
    shift_time2: float = setting(0.5, 'duration T2 of the second shift', unit='s', low=0.0)

    @property
    def stance(self) -> StanceSchedule:
        """The moving stance schedule of the shift_* fields."""
        return StanceSchedule(self.shift_y1, self.shift_z1, self.shift_time1, self.shift_y2,
                              self.shift_time2)


@dataclass(frozen=True)
class BalanceParameters(_Block, prefix='balance.'):
    """Parameters of the walking stabiliser (values found by random search, see
    scripts/tune_gait.py)."""

    swing_time: float = setting(0.45, 'duration of the swing-foot path after the exchange',
                                unit='s', low=0.05, high=2.0)
    glide_time: float = setting(0.0, 'time after the exchange the lifted swing foot waits '
                                'behind the hip before it swings forward (a glide on the '
                                'support foot)', unit='s', low=0.0, high=2.0)
    clearance: float = setting(0.04, 'height the swing ankle rises above its floor height',
                               unit='m', low=0.0, high=0.2)
    press: float = setting(0.02, 'depth below the floor the swing path ends at (makes the heel '
                           'strike)', unit='m', low=0.0, high=0.1)
    lift_fraction: float = setting(0.25, 'fraction of swing_time spent rising', low=0.01,
                                   high=1.0)
    descent_start: float = setting(0.6, 'fraction of swing_time after which the path descends',
                                   low=0.0, high=0.99)
    step_length: float = setting(0.3, 'nominal step; the foot lands half of it ahead of the '
                                 'CoM', unit='m', low=0.0, high=1.0)
    placement_gain: float = setting(0.2, 'extra landing distance per m/s of speed error',
                                    unit='s', low=-1.0, high=1.0)
    speed: float = setting(0.4, 'desired forward CoM speed v_d (reached over the first 0.5 s)',
                           unit='m/s', low=-1.0, high=2.0)
    speed_gain: float = setting(100.0, 'k_v of the virtual forward force', unit='N s/m',
                                low=0.0)
    pace_gain: float = setting(0.0, "virtual force per m the head top lags behind the pace "
                               "point, which leaves the head's start at t = 0 at speed v_d",
                               unit='N/m', low=0.0)
    feedback_limit: float = setting(0.0, 'bound of the speed and pace terms together (0: none): '
                                    'after a push the robot keeps some of the speed it got '
                                    'instead of braking, which on ice only slides the support '
                                    'foot forward', unit='N', low=0.0)
    drive: float = setting(0.0, 'constant part F_0 of the virtual force (reached over the '
                           "first 0.5 s): the push that makes up for the ice's losses at speed",
                           unit='N', low=-100.0, high=100.0)
    max_force: float = setting(40.0, 'bound of the virtual force forward', unit='N', low=0.0)
    max_brake: float = setting(40.0, 'bound of the virtual force backward (on ice braking only '
                               'slides the support foot forward)', unit='N', low=0.0)
    com_stiffness: float = setting(0.0, 'support-ankle feedback on the CoM distance ahead of '
                                   'the support ankle minus com_offset (ankle strategy)',
                                   unit='N m/m', low=0.0)
    com_damping: float = setting(0.0, 'support-ankle rate feedback on v_com - v_ankle',
                                 unit='N m s/m', low=0.0)
    com_offset: float = setting(0.0, 'desired distance of the CoM ahead of the support ankle',
                                unit='m', low=-0.2, high=0.2)
    stance_knee: float = setting(0.1, 'support knee angle (flexion > 0)', unit='rad', low=0.0,
                                 high=1.5)
    trunk: float = setting(0.0, 'pelvis pitch phi_4 held in the world frame (> 0 leans back)',
                           unit='rad', low=-0.5, high=0.5)
    stiffness: float = setting(800.0, 'PD stiffness of the support knee, hip and torso',
                               unit='N m/rad', low=0.0)
    ankle_stiffness: float = setting(30.0, 'PD stiffness of the support ankle', unit='N m/rad',
                                     low=0.0)
    ankle_damping: float = setting(5.0, 'PD damping of the support ankle', unit='N m s/rad',
                                   low=0.0)
    swing_stiffness: float = setting(300.0, 'PD stiffness of the swing hip and knee in the air',
                                     unit='N m/rad', low=0.0)
    swing_damping: float = setting(30.0, 'PD damping of the swing hip and knee in the air',
                                   unit='N m s/rad', low=0.0)
    front_hip_stiffness: float = setting(300.0, 'PD stiffness of the front hip in double '
                                         'support', unit='N m/rad', low=0.0)
    front_knee_stiffness: float = setting(300.0, 'PD stiffness of the front knee in double '
                                          'support', unit='N m/rad', low=0.0)
    push: float = setting(20.0, 'rear-ankle push-off torque reached push_ramp after the heel '
                          'strike', unit='N m', low=-100.0, high=200.0)
    push_ramp: float = setting(0.3, 'ramp time of the push-off torque and the rear knee flexion',
                               unit='s', low=0.0)
    toe_off_flex: float = setting(0.5, 'rear knee angle reached at the end of push_ramp',
                                  unit='rad', low=0.0, high=1.5)
    blend: float = setting(0.2, 'time over which the support references move from the current '
                           'angles to their nominal values after an exchange', unit='s',
                           low=0.0, high=2.0)
    front_knee_step: float = setting(0.0, 'largest distance of the front knee reference from '
                                     'the current angle in double support (0: no bound)',
                                     unit='rad', low=0.0, high=2.0)


@dataclass(frozen=True)
class FeedforwardParameters(_Block, prefix='feedforward.'):
    """Parameters of the feed-forward leg torques (docs/model.md, feed-forward pulses)."""

    hip_amplitude: float = setting(40.0, 'A5, amplitude of the swing-hip pulse', unit='N m',
                                   low=0.0)
    hip_duration: float = setting(0.35, 'D5, duration of the swing-hip pulse', unit='s',
                                  low=0.0, open_low=True)
    knee_amplitude: float = setting(20.0, 'A6, amplitude of the swing-knee flexion pulse '
                                    '(15-25 work)', unit='N m', low=0.0)
    knee_duration: float = setting(0.25, 'D6, duration of the swing-knee pulse', unit='s',
                                   low=0.0, open_low=True)
    knee_stiffness: float = setting(50.0, 'K6 of the swing-knee extension PD after the pulse',
                                    unit='N m/rad', low=0.0)
    knee_reference: float = setting(-0.05, 'q6_ref of the swing-knee extension PD (slightly '
                                    'flexed)', unit='rad', low=-2.5, high=0.0)
    knee_damping: float = setting(5.0, 'B6 of the swing-knee extension PD', unit='N m s/rad',
                                  low=0.0)
    ankle_push: float = setting(20.0, 'A2, support-ankle push-off (plantar flexion)',
                                unit='N m', low=0.0)
    knee_push: float = setting(10.0, 'A3, support-knee extension during push-off', unit='N m',
                               low=0.0)
    pivot_push: float = setting(10.0, 'A1, heel-up torque on the floor pivot q1 during '
                                'push-off', unit='N m', low=0.0)
    joint1_torque: bool = setting(True, 'apply the q1 (floor pivot) entry at all')


@dataclass(frozen=True)
class WeightTransferParameters(_Block, prefix='weight_transfer.'):
    """Parameters of the weight transfer after heel strike (docs/model.md, weight transfer)."""

    share: float = setting(1.0, 'final f_des as a fraction of the weight m g (1: full '
                           'transfer, the rear normal force reaches 0; 0.3 settles in double '
                           "support); the 'com' rule's upper bound", low=0.0, high=2.0)
    ramp_time: float = setting(0.5, 'time of the linear ramp of f_des from 0 after the heel '
                               'strike', unit='s', low=0.0)
    moment_arm: float = setting(0.05, 'tau_n,des / f_des while the front sole is flat (0 '
                                'disables)', unit='m', low=-0.26, high=0.26)
    joint1_torque: bool = setting(True, 'apply the q1 (floor pivot) entry while q1 is active')
    start_share: float = setting(0.5, 'f_des / (m g) on the second foot in the starting double '
                                 'support (weight shift before the first step)', low=0.0,
                                 high=1.0)
    start_ramp: float = setting(0.5, 'time over which the starting share falls linearly to 0 '
                                '(unloading the swing foot for lift-off); 0 holds it',
                                unit='s', low=0.0)
    rule: str = setting('ramp', "'ramp' (time ramp to share) or 'com' (static split by the "
                        'capture point)', choices=WEIGHT_RULES)
    capture_gain: float = setting(1.0, "'com' rule: weight of v sqrt(z/g) in y_x (1: the "
                                  'capture point)', low=0.0, high=5.0)
    share_min: float = setting(0.0, "'com' rule: lower bound of the share, reached linearly "
                               'over ramp_time after the heel strike', low=0.0, high=2.0)
    heel_share: float = setting(2.0, "'com' rule: upper bound of the share while only the "
                                'front heel touches (2: none)', low=0.0, high=2.0)
    heel_time: float = setting(0.0, "'com' rule: time after the heel strike from which "
                               'the heel_share bound rises to share over ramp_time, so a '
                               'front sole that does not come flat takes the load on its heel '
                               '(0: the bound holds)', unit='s', low=0.0)


@dataclass(frozen=True)
class HeelParameters(_Block, prefix='heel.'):
    """Parameters of the heel-first landing input (docs/model.md, heel-first landing)."""

    stiffness: float = setting(150.0, 'K7 of the swing-sole pitch PD in the air (30 lets the '
                               'toe scuff)', unit='N m/rad', low=0.0)
    damping: float = setting(6.0, 'B7 of the swing-sole pitch PD in the air', unit='N m s/rad',
                             low=0.0)
    landing_pitch: float = setting(0.15, 'theta_land, landing sole pitch (toe up)', unit='rad',
                                   low=-0.5, high=0.5)
    ramp_time: float = setting(0.15, 'time over which theta_land ramps linearly from 0 after '
                               'the exchange', unit='s', low=0.0)
    contact_stiffness: float = setting(30.0, 'K of the PD to a flat sole with the heel on the '
                                       'floor (Hs, Hp)', unit='N m/rad', low=0.0)
    contact_damping: float = setting(3.0, 'B of the PD to a flat sole with the heel on the '
                                     'floor', unit='N m s/rad', low=0.0)


@dataclass(frozen=True)
class ArmAssistParameters(_Block, prefix='arm_assist.'):
    """Parameters of the arm assist (docs/model.md, arm assist)."""

    amplitude: float = setting(2.0, 'A_arm, amplitude of the shoulder sinusoid', unit='N m',
                               low=0.0)
    period: float = setting(1.85, 'T of the phase (as in eq. 10)', unit='s', low=0.0,
                            open_low=True)
    phase: str = setting('B', "phase reading, as for the yaw input: 'B' 2 pi (t - t_e)/T, 'A' "
                         "2 (t - t_e)/T, 'B_clipped' reading B clipped to [0, pi]",
                         choices=PHASE_READINGS)
    stiffness: float = setting(10.0, 'K of the elbow and wrist PD to 0', unit='N m/rad',
                               low=0.0)
    damping: float = setting(1.0, 'B of the elbow and wrist PD', unit='N m s/rad', low=0.0)
    off_from_step_index: int = setting(3, 'the assist stops once step_index reaches this many '
                                       'exchanges (3: from the 4th step on)', low=0)
    release_time: float = setting(0.0, 'duration of the shoulder brake at the start of the first '
                                  'step without assist (0: none)', unit='s', low=0.0)
    release_damping: float = setting(0.0, 'initial damping of the shoulder brake (joints 11, '
                                     '14), faded out over release_time', unit='N m s/rad',
                                     low=0.0)


@dataclass(frozen=True)
class YawParameters(_Block, prefix='yaw.'):
    """Parameters of the torso-yaw input, eq. (10) (docs/model.md, torso yaw)."""

    amplitude: float = setting(30.0, 'A of eq. (10)', unit='N m', low=0.0)
    period: float = setting(1.85, 'T of eq. (10)', unit='s', low=0.0, open_low=True)
    phase: str = setting('B', "phase reading: 'B' Phi = 2 pi (t - t_e)/T, 'A' Phi = 2 (t - "
                         "t_e)/T (the literal text), 'B_clipped' reading B clipped to [0, pi]",
                         choices=PHASE_READINGS)


@dataclass(frozen=True)
class GaitManagerParameters(_Block):
    """All gait-manager parameter blocks and the set of enabled sources (default: all);
    ``from_dict`` takes a nested mapping {block: {key: value}, 'enabled': [sources]} (missing
    blocks keep their defaults; an error names the dotted key, e.g. 'posture.stiffness')."""

    posture: PostureParameters = block(
        PostureParameters, "posture stabiliser and stance reference (source 'posture')")
    balance: BalanceParameters = block(
        BalanceParameters, "walking stabiliser (source 'posture' with reference 'balance')")
    feedforward: FeedforwardParameters = block(
        FeedforwardParameters, "swing pulses and push-off (source 'feedforward')")
    weight_transfer: WeightTransferParameters = block(
        WeightTransferParameters, "weight transfer after heel strike (source 'weight_transfer')")
    heel: HeelParameters = block(HeelParameters, "heel-first landing input (source 'heel')")
    arm_assist: ArmAssistParameters = block(
        ArmAssistParameters, "arm assist of steps 1-3 (source 'arm_assist')")
    yaw: YawParameters = block(YawParameters, "torso-yaw input of eq. (10) (source 'yaw')")
    enabled: frozenset[str] = setting(frozenset(SOURCES), 'torque sources to compute and send',
                                      choices=SOURCES)


def head_stance(params: GaitManagerParameters) -> StanceSchedule | None:
    """The moving stance visual lifting's head target should follow: the posture source's
    schedule while it runs with the 'moving' reference, else None (no shift)."""
    if 'posture' not in params.enabled or params.posture.reference != 'moving':
        return None
    return params.posture.stance
