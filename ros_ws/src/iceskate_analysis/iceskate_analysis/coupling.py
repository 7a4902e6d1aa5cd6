"""The paper's eq. (11) at one joint, evaluated on a recorded run (no re-simulation), and the
arm swing of both shoulders. The terms, their signs and the closure check are those of
docs/model.md §13; the interval-averaged accelerations are described in docs/usage.md.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field, replace
import functools
import hashlib
import pathlib
import tempfile
from typing import Any

import numpy as np
import pinocchio as pin

from iceskate_analysis.bag_io import PASSIVE, BagData
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import ContactState, DynamicsParameters, ModelTerms
from iceskate_sim.model.modes import MULTIPLIER_NAMES, get_mode
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, Q1, Y0, Robot, load_robot
from iceskate_sim.progress import ProgressBar
from iceskate_sim.run.metrics import ARM_SWING_FROM_STEP

__all__ = ['ArmSwing', 'CaseResult', 'JointDecomposition', 'RIGHT_SHOULDER', 'LEFT_SHOULDER',
           'TERMS', 'analyse_case', 'arm_swing', 'decompose', 'dynamics_for_bag',
           'mirror_joint', 'parse_joint', 'robot_for_bag', 'rms', 'write_csv']

RIGHT_SHOULDER = 11
LEFT_SHOULDER = 14
TORSO_YAW = 8
#: Fewest samples for an arm-swing window; shorter windows fall back to the whole run.
MIN_WINDOW = 8
#: Terms of eq. (11), in the order of the equation (keys of JointDecomposition.terms()).
TERMS = ('own_inertia', 'tau', 'm_total', 'coriolis', 'gravity', 'damping', 'limit',
         'constraint', 'support_friction', 'residual')
#: Sources that are external forces on a link (recorded as J^T f), not joint inputs.
EXTERNAL_SOURCES = ('push',)
#: Rows of a CSV file turned into text at a time (``write_csv``).
CSV_BLOCK = 4096
_HEEL_SPEED_EPS = 1e-9  # m/s: below it a sliding heel's friction direction defaults to +1


def parse_joint(value: str | int) -> int:
    """Joint index of '11', 11 or 'q11' (0 or 'y0' for y0).

    :raises SimulationError: for anything that is not one of the 18 coordinates.
    """
    text = str(value).strip()
    if text in COORDINATE_NAMES:
        return COORDINATE_NAMES.index(text)
    try:
        index = int(text)
    except ValueError:
        index = -1
    if not 0 <= index < N_COORDINATES:
        raise SimulationError(f'unknown joint {value!r}: give 0..17 or one of '
                              f'{list(COORDINATE_NAMES)} (11 = right shoulder, 14 = left)')
    return index


def mirror_joint(joint: int) -> int | None:
    """The other arm's shoulder for a shoulder (11 <-> 14), else None."""
    return {RIGHT_SHOULDER: LEFT_SHOULDER, LEFT_SHOULDER: RIGHT_SHOULDER}.get(joint)


def rms(x: np.ndarray) -> float:
    """Root mean square over the finite entries (nan when there is none)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else float('nan')


# ------------------------------------------------------------------------- the model of a bag
def robot_for_bag(bag: BagData) -> Robot:
    """The robot the run used: the bag's URDF when it carries one, else the installed one."""
    robot = load_robot()
    if not bag.urdf:
        return robot
    try:
        installed = robot.urdf_path.read_text(encoding='utf-8')
    except OSError:
        installed = ''
    if bag.urdf == installed:
        return robot
    digest = hashlib.sha256(bag.urdf.encode('utf-8')).hexdigest()[:16]
    path = pathlib.Path(tempfile.gettempdir()) / f'iceskate_bag_urdf_{digest}.urdf'
    if not path.is_file():
        path.write_text(bag.urdf, encoding='utf-8')
    return load_robot(str(path))


def dynamics_for_bag(bag: BagData, robot: Robot | None = None) -> ModelTerms:
    """ModelTerms with the run's friction coefficient and joint-damping switch.

    Both come from the bag's scene parameters (floor.mu, dynamics.damping); a bag without them
    gets the scene defaults (mu 0.005, damping on).
    """
    scene = bag.scene_parameters
    floor = scene.get('floor') or {}
    dyn = scene.get('dynamics') or {}
    params = DynamicsParameters(mu=float(floor.get('mu', DynamicsParameters.mu)),
                                damping=bool(dyn.get('damping', True)))
    return ModelTerms(robot or robot_for_bag(bag), params)


# ------------------------------------------------------------------------ the decomposition
@dataclass(frozen=True)
class JointDecomposition:
    """Eq. (11) at joint ``joint`` for every sample (arrays (N,), nan where inactive).

    Units: N m (N for y0). ``coupling[:, j]`` is M_ij q̈_j (0 for j = i and inactive j).
    """

    joint: int
    t: np.ndarray
    valid: np.ndarray
    own_inertia: np.ndarray
    coupling: np.ndarray
    coriolis: np.ndarray
    gravity: np.ndarray
    damping: np.ndarray
    tau: np.ndarray
    tau_by_source: dict[str, np.ndarray]
    passive: np.ndarray
    constraint: np.ndarray
    support_friction: np.ndarray
    mass_row: np.ndarray = field(repr=False)

    @property
    def name(self) -> str:
        """Coordinate name, e.g. 'q11'."""
        return COORDINATE_NAMES[self.joint]

    @property
    def m_total(self) -> np.ndarray:
        """M_total = −Σ_{j≠i} M_ij q̈_j [N m]."""
        return -self.coupling.sum(axis=1)

    @property
    def limit(self) -> np.ndarray:
        """Soft-stop torque: the recorded passive effort minus the joint damping [N m]."""
        return self.passive + self.damping

    @property
    def rhs(self) -> np.ndarray:
        """Right side of eq. (11)."""
        return (self.tau + self.m_total - self.coriolis - self.gravity + self.passive
                + self.constraint + self.support_friction)

    @property
    def residual(self) -> np.ndarray:
        """Closure residual M_ii q̈_i − right side [N m]."""
        return self.own_inertia - self.rhs

    @property
    def scale(self) -> np.ndarray:
        """Sum of the magnitudes of every term of the row (the relative-residual base)."""
        return (np.abs(self.own_inertia) + np.abs(self.coupling).sum(axis=1)
                + np.abs(self.coriolis) + np.abs(self.gravity) + np.abs(self.damping)
                + np.abs(self.limit) + np.abs(self.tau) + np.abs(self.constraint)
                + np.abs(self.support_friction))

    @property
    def residual_rel(self) -> np.ndarray:
        """|residual| / scale per sample (0 where every term is 0, nan where inactive)."""
        scale = self.scale
        with np.errstate(invalid='ignore', divide='ignore'):
            rel = np.where(scale > 0.0, np.abs(self.residual) / scale, 0.0)
        return np.where(self.valid, rel, np.nan)

    def terms(self) -> dict[str, np.ndarray]:
        """The terms of eq. (11), keyed as in TERMS."""
        return {name: getattr(self, name) for name in TERMS}

    def coupling_series(self) -> dict[str, np.ndarray]:
        """M_ij q̈_j per other coordinate j that is active somewhere, keyed by j's name."""
        return {COORDINATE_NAMES[j]: self.coupling[:, j] for j in range(N_COORDINATES)
                if j != self.joint and np.any(self.coupling[self.valid, j] != 0.0)}

    def period_averaged(self, accelerations: np.ndarray, defined: np.ndarray
                        ) -> JointDecomposition:
        """The row with ``accelerations`` (N, 18), e.g. ``interval_accelerations``, in place of
        the recorded q̈ in M_ii q̈_i and M_total; valid only where they are ``defined``."""
        valid = self.valid & defined
        own, coupling = _inertia_terms(self.mass_row, accelerations, valid, self.joint)
        return replace(self, valid=valid, own_inertia=own, coupling=coupling)

    def ranking(self, mask: np.ndarray | None = None) -> list[tuple[str, float]]:
        """Coupling terms M_ij q̈_j by decreasing RMS over ``mask`` (default: valid samples)."""
        mask = self.valid if mask is None else mask & self.valid
        ranked = [(name, rms(x[mask])) for name, x in self.coupling_series().items()]
        return sorted(ranked, key=lambda item: -item[1] if np.isfinite(item[1]) else 0.0)


def _inertia_terms(mass_row: np.ndarray, accelerations: np.ndarray, valid: np.ndarray,
                   joint: int) -> tuple[np.ndarray, np.ndarray]:
    """M_ii q̈_i (N,) and M_ij q̈_j with column i zeroed (N, 18) [N m] of ``accelerations``
    (N, 18), nan where not ``valid``."""
    terms = np.where(valid[:, None], mass_row * accelerations, np.nan)
    own = terms[:, joint].copy()
    terms[:, joint] = np.where(valid, 0.0, np.nan)
    return own, terms


def interval_accelerations(bag: BagData) -> tuple[np.ndarray, np.ndarray]:
    """The accelerations the integrator produced over each sampling interval,
    (v_{k+1} - v_k) / (t_{k+1} - t_k) (N, 18) [m/s², rad/s²], and where they are defined (N,):
    no transition in (t_k, t_{k+1}] (no impact and no re-rooted coordinates in between, also
    none that went out and back between two samples of a thinned bag) and the same mode,
    support side, pivot and step at both ends; never at the last sample."""
    n = bag.n_samples
    out = np.full((n, N_COORDINATES), np.nan)
    defined = np.zeros(n, dtype=bool)
    if n >= 2:
        same = ((bag.mode[1:] == bag.mode[:-1]) & (bag.side[1:] == bag.side[:-1])
                & (bag.pivot[1:] == bag.pivot[:-1])
                & (bag.step_index[1:] == bag.step_index[:-1])
                & (bag.last_transition_ns[1:] <= bag.t_ns[:-1]))
        dt = np.diff(bag.t)[:, None]
        out[:-1] = np.where(same[:, None], (bag.v[1:] - bag.v[:-1]) / dt, np.nan)
        defined[:-1] = same
    return out, defined


def _constraint_force(dyn: ModelTerms, contact: ContactState, q: np.ndarray, v: np.ndarray,
                      multipliers: np.ndarray, data: dict[tuple[str, str], pin.Data]
                      ) -> np.ndarray:
    """Generalized force of the active swing constraints (18,), heel friction included."""
    mode = contact.mode
    rows = dyn.constraint_jacobian(contact, q)
    lam = np.array([multipliers[MULTIPLIER_NAMES.index(m)] for m in mode.multipliers])
    cols = rows.copy()
    if mode.swing_sliding:  # Coulomb friction mu f_nz on the heel, against its y velocity
        sm = dyn.robot.support_model(contact.side, contact.pivot)
        d = data.setdefault((sm.side, sm.pivot), sm.new_data())
        jac = pin.computeFrameJacobian(sm.model, d, q, sm.frame_ids['swing_heel'],
                                       pin.LOCAL_WORLD_ALIGNED)
        heel_y = jac[1].copy()
        heel_y[~np.isin(np.arange(N_COORDINATES), mode.active)] = 0.0
        speed = float(heel_y @ v)
        direction = np.sign(speed) if abs(speed) > _HEEL_SPEED_EPS else 1.0
        cols[0] = cols[0] - dyn.params.mu * direction * heel_y
    return cols.T @ lam


def decompose(bag: BagData, joints: tuple[int, ...] = (RIGHT_SHOULDER,),
              dynamics: ModelTerms | None = None, progress: bool = False,
              ) -> dict[int, JointDecomposition]:
    """Evaluate eq. (11) at each of ``joints`` for every sample of ``bag``.

    :param joints: coordinate indices (0 = y0, 1..17 = q1..q17).
    :param dynamics: the model to use (default: :func:`dynamics_for_bag`).
    :param progress: show a tqdm progress bar.
    :return: joint -> its decomposition.
    :raises SimulationError: for an unknown joint or a sample the model cannot evaluate.
    """
    joints = tuple(parse_joint(j) for j in joints)
    dyn = dynamics or dynamics_for_bag(bag)
    n = bag.n_samples
    nj = len(joints)
    mass_row = np.zeros((nj, n, N_COORDINATES))
    coriolis = np.full((nj, n), np.nan)
    gravity = np.full((nj, n), np.nan)
    constraint = np.zeros((nj, n))
    valid = np.zeros((nj, n), dtype=bool)
    pin_data: dict[tuple[str, str], pin.Data] = {}
    bar = ProgressBar(n, f'eq. (11) {bag.path.name}', 'sample', progress, leave=False)
    try:
        for k in range(n):
            mode = get_mode(int(bag.mode[k]))
            contact = ContactState(mode, bag.side_name(k), bag.pivot_name(k),
                                   float(bag.heel_anchor_y[k]))
            q, v = bag.q[k], bag.v[k]
            act = mode.active
            try:
                M = dyn.mass_matrix(contact, q)
                h = dyn.bias_terms(contact, q, v)
                g = dyn.gravity_terms(contact, q)
                force = (_constraint_force(dyn, contact, q, v, bag.multipliers[k], pin_data)
                         if mode.constraints else np.zeros(N_COORDINATES))
            except SimulationError as exc:
                raise SimulationError(f'{bag.path}: cannot evaluate the model at sample {k} '
                                      f'(t = {bag.t[k]:.6f} s, mode {mode.number}): {exc}'
                                      ) from exc
            for a, i in enumerate(joints):
                where = np.flatnonzero(act == i)
                if not where.size:
                    continue
                p = int(where[0])
                mass_row[a, k, act] = M[p]
                coriolis[a, k] = h[p]
                gravity[a, k] = g[p]
                constraint[a, k] = force[i]
                valid[a, k] = True
            bar.update(1)
    finally:
        bar.close()
    damping_coefficients = dyn.robot.damping if dyn.params.damping else np.zeros(N_COORDINATES)
    passive = bag.efforts.get(PASSIVE, np.zeros((n, N_COORDINATES)))
    out = {}
    for a, i in enumerate(joints):
        by_source = {s: np.where(_actuated(bag, i, s), bag.efforts[s][:, i], 0.0)
                     for s in bag.sources}
        tau = np.sum(list(by_source.values()), axis=0) if by_source else np.zeros(n)
        friction = (np.where(bag.active[:, Y0], bag.support_friction, 0.0) if i == Y0
                    else np.zeros(n))
        nan = ~valid[a]
        own, coupling = _inertia_terms(mass_row[a], bag.qdd, valid[a], i)
        out[i] = JointDecomposition(
            joint=i, t=bag.t, valid=valid[a], own_inertia=own, coupling=coupling,
            coriolis=coriolis[a], gravity=gravity[a],
            damping=_masked(damping_coefficients[i] * bag.v[:, i], nan),
            tau=_masked(tau, nan), tau_by_source={s: _masked(x, nan) for s, x in
                                                  by_source.items()},
            passive=_masked(passive[:, i], nan), constraint=_masked(constraint[a], nan),
            support_friction=_masked(friction, nan), mass_row=mass_row[a])
    return out


def _actuated(bag: BagData, i: int, source: str) -> np.ndarray:
    """Whether ``source`` acts on coordinate i at each sample.

    Joint inputs never act on y0 (unactuated) and on q1 only while it is a coordinate; an
    external force (``push``) acts on every active coordinate.
    """
    if source in EXTERNAL_SOURCES:
        return bag.active[:, i].copy()
    if i == Y0:
        return np.zeros(bag.n_samples, dtype=bool)
    if i == Q1:
        return bag.active[:, Q1].copy()
    return np.ones(bag.n_samples, dtype=bool)


def _masked(x: np.ndarray, nan: np.ndarray) -> np.ndarray:
    return np.where(nan, np.nan, np.asarray(x, dtype=float))


# ----------------------------------------------------------------------------- arm swing
@dataclass(frozen=True)
class ArmSwing:
    """Swing of both shoulders over the analysis window.

    :ivar window_from_step: step index the window starts at (None: whole run).
    :ivar window_start_s: time of the window's first sample [s].
    :ivar samples: samples in the window.
    :ivar peak_to_peak: q11 and q14 peak-to-peak [rad].
    :ivar dominant_frequency: q11 and q14 strongest non-zero FFT frequency [Hz].
    :ivar correlation: Pearson correlation of q11 and q14 (−1: mirror images).
    :ivar phase_difference_deg: phase of q11 relative to q14 from the Hilbert transform
        (amplitude-weighted mean over the window), in (−180, 180]; ±180 is anti-phase.
    """

    window_from_step: int | None
    window_start_s: float
    samples: int
    peak_to_peak: dict[str, float]
    dominant_frequency: dict[str, float]
    correlation: float
    phase_difference_deg: float

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        arms = {name: {'peak_to_peak_rad': self.peak_to_peak[name],
                       'peak_to_peak_deg': float(np.degrees(self.peak_to_peak[name])),
                       'dominant_frequency_hz': self.dominant_frequency[name]}
                for name in self.peak_to_peak}
        return {'window': {'from_step_index': self.window_from_step,
                           'start_s': self.window_start_s, 'samples': self.samples},
                **arms, 'correlation': self.correlation,
                'phase_difference_deg': self.phase_difference_deg}


def analysis_window(bag: BagData) -> tuple[np.ndarray, int | None]:
    """Mask of the samples from ``step_index >= ARM_SWING_FROM_STEP`` on (and that step), or
    all (and None) when too few."""
    mask = bag.step_index >= ARM_SWING_FROM_STEP
    if int(mask.sum()) >= MIN_WINDOW:
        return mask, ARM_SWING_FROM_STEP
    return np.ones(bag.n_samples, dtype=bool), None


def _dominant_frequency(t: np.ndarray, x: np.ndarray) -> float:
    if x.size < 4 or not np.any(x != x[0]):
        return float('nan')
    dt = float(np.mean(np.diff(t)))
    spectrum = np.abs(np.fft.rfft(x - x.mean()))
    freqs = np.fft.rfftfreq(x.size, dt)
    return float(freqs[1:][np.argmax(spectrum[1:])]) if freqs.size > 1 else float('nan')


def arm_swing(bag: BagData) -> ArmSwing:
    """Peak-to-peak, frequency, correlation and phase of q11 versus q14 (``analysis_window``)."""
    from scipy.signal import detrend, hilbert
    mask, step = analysis_window(bag)
    t = bag.t[mask]
    right, left = bag.q[mask, RIGHT_SHOULDER], bag.q[mask, LEFT_SHOULDER]
    p2p = {'q11': float(np.ptp(right)) if right.size else float('nan'),
           'q14': float(np.ptp(left)) if left.size else float('nan')}
    freq = {'q11': _dominant_frequency(t, right), 'q14': _dominant_frequency(t, left)}
    correlation = phase = float('nan')
    if right.size >= 4:
        a, b = detrend(right), detrend(left)
        if np.std(a) > 0.0 and np.std(b) > 0.0:
            correlation = float(np.corrcoef(a, b)[0, 1])
            za, zb = hilbert(a), hilbert(b)
            phase = float(np.degrees(np.angle(np.sum(za * np.conj(zb)))))
            if phase <= -180.0:
                phase += 360.0
    return ArmSwing(step, float(t[0]) if t.size else float('nan'), int(mask.sum()), p2p, freq,
                    correlation, phase)


# ------------------------------------------------------------------------------ one case
@dataclass
class CaseResult:
    """Everything computed for one bag."""

    label: str
    bag: BagData
    joint: int
    decompositions: dict[int, JointDecomposition]
    arms: ArmSwing
    window: np.ndarray = field(repr=False)

    @property
    def main(self) -> JointDecomposition:
        """The decomposition of the chosen joint."""
        return self.decompositions[self.joint]

    @property
    def torso_yaw_input(self) -> bool:
        """Whether a 'yaw' source (the τ8 of eq. 10) commanded the torso yaw q8."""
        yaw = self.bag.efforts.get('yaw')
        return bool(yaw is not None and np.any(yaw[:, TORSO_YAW] != 0.0))

    @property
    def fourth_step_s(self) -> float | None:
        """Start of the paper's 4th step [s] (first sample with step_index >= 3)."""
        return self.bag.step_start_time(ARM_SWING_FROM_STEP)

    @functools.cached_property
    def interval(self) -> tuple[np.ndarray, np.ndarray]:
        """``interval_accelerations`` of the bag."""
        return interval_accelerations(self.bag)

    def averaged(self, d: JointDecomposition) -> JointDecomposition:
        """``d`` with the accelerations averaged over each sampling interval."""
        return d.period_averaged(*self.interval)

    def paper_reading(self, d: JointDecomposition) -> dict[str, float]:
        """The figures the paper's reading of Figs. 7/8 rests on, over the window, with the
        recorded (instantaneous) and the interval-averaged accelerations: RMS(M_total - g_i) /
        RMS(g_i) (small if M_total ~ g_i) and RMS(h_i) (what τ8 changes)."""
        out = {}
        for view, x in (('instantaneous', d), ('interval_averaged', self.averaged(d))):
            mask = self.window & x.valid
            gravity = rms(x.gravity[mask])
            out[f'rms_m_total_minus_g_over_rms_g_{view}'] = (
                rms((x.m_total - x.gravity)[mask]) / gravity if gravity > 0.0
                else float('nan'))
            out[f'rms_m_total_{view}'] = rms(x.m_total[mask])
        out['rms_g'] = rms(d.gravity[self.window & d.valid])
        out['rms_h'] = rms(d.coriolis[self.window & d.valid])
        return out

    def joint_summary(self, d: JointDecomposition) -> dict[str, Any]:
        """Closure, RMS of every term and the coupling ranking of one joint."""
        mask = self.window & d.valid
        rel = d.residual_rel[d.valid]
        terms = d.terms()
        averaged = self.averaged(d)
        averaged_mask = self.window & averaged.valid
        out: dict[str, Any] = {
            'samples_valid': int(d.valid.sum()),
            'closure_residual_max_rel': float(rel.max()) if rel.size else float('nan'),
            'closure_residual_max_abs': float(np.max(np.abs(d.residual[d.valid])))
            if rel.size else float('nan'),
            'rms': {name: rms(x[mask]) for name, x in terms.items()},
            'rms_tau_by_source': {s: rms(x[mask]) for s, x in d.tau_by_source.items()},
            'rms_m_total_minus_g': rms((d.m_total - d.gravity)[mask]),
            'rms_sum_minus_g': rms((-d.m_total - d.gravity)[mask]),
            'coupling_ranking': [{'coordinate': name, 'rms': value}
                                 for name, value in d.ranking(mask)],
            'interval_averaged': {
                'samples_valid': int(averaged.valid.sum()),
                'rms': {name: rms(x[averaged_mask]) for name, x in averaged.terms().items()
                        if name != 'residual'},
                'coupling_ranking': [{'coordinate': name, 'rms': value}
                                     for name, value in averaged.ranking(averaged_mask)],
            },
            'paper_reading': self.paper_reading(d),
        }
        if np.any(d.valid):
            out['mean_M_i8'] = float(np.mean(d.mass_row[d.valid, TORSO_YAW]))
        else:
            out['note'] = f'{d.name} is a coordinate of none of the recorded modes'
        return out

    def summary(self) -> dict[str, Any]:
        """The summary.json entry of this case."""
        bag = self.bag
        main = self.joint_summary(self.main)
        return {
            'bag': str(bag.path), 'scene': bag.scene_name, 'samples': bag.n_samples,
            'duration_s': float(bag.t[-1] - bag.t[0]), 'steps': int(bag.step_index.max()),
            'sources': list(bag.sources), 'torso_yaw_input': self.torso_yaw_input,
            'fourth_step_s': self.fourth_step_s,
            'rms_window': {'from_step_index': self.arms.window_from_step,
                           'start_s': self.arms.window_start_s,
                           'samples': int(self.window.sum())},
            'joint': self.main.name,
            'closure_residual_max_rel': main['closure_residual_max_rel'],
            'closure_residual_max_abs': main['closure_residual_max_abs'],
            'arms': self.arms.as_dict(),
            **{key: main[key] for key in ('rms', 'rms_tau_by_source', 'rms_m_total_minus_g',
                                          'rms_sum_minus_g', 'coupling_ranking')},
            'joints': {d.name: self.joint_summary(d) for d in self.decompositions.values()},
            'notes': list(bag.notes),
        }


def analyse_case(bag: BagData, label: str, joint: int = RIGHT_SHOULDER,
                 progress: bool = False) -> CaseResult:
    """Decompose eq. (11) at ``joint`` (and at the other shoulder for a shoulder) and measure
    the arm swing."""
    joint = parse_joint(joint)
    joints = (joint,) + ((mirror_joint(joint),) if mirror_joint(joint) is not None else ())
    decompositions = decompose(bag, joints, progress=progress)
    window, _ = analysis_window(bag)
    return CaseResult(label, bag, joint, decompositions, arm_swing(bag), window)


# ---------------------------------------------------------------------------------- export
def write_csv(path: str | pathlib.Path, columns: dict[str, np.ndarray]) -> pathlib.Path:
    """Write equal-length columns to a CSV file with a header row (nan written as 'nan'), in
    blocks of ``CSV_BLOCK`` rows, so that the text in memory is bounded whatever the length.

    :raises ValueError: when the columns differ in length.
    """
    path = pathlib.Path(path)
    arrays = [np.asarray(a) for a in columns.values()]
    lengths = {len(a) for a in arrays}
    if len(lengths) > 1:
        raise ValueError(f'columns of different lengths {sorted(lengths)} for {path}')
    with path.open('w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(columns)
        for start in range(0, lengths.pop() if lengths else 0, CSV_BLOCK):
            text = [[str(int(x)) for x in block] if block.dtype.kind in 'biu'
                    else [repr(float(x)) for x in block]
                    for block in (a[start:start + CSV_BLOCK] for a in arrays)]
            writer.writerows(zip(*text, strict=True))
    return path


def case_columns(case: CaseResult) -> dict[str, np.ndarray]:
    """Every time series of a case: the state of both arms and the terms of every joint."""
    bag = case.bag
    cols: dict[str, np.ndarray] = {
        't_s': bag.t, 'mode': bag.mode, 'support_side': bag.side, 'pivot': bag.pivot,
        'step_index': bag.step_index,
        'q11': bag.q[:, RIGHT_SHOULDER], 'q14': bag.q[:, LEFT_SHOULDER],
        'qd11': bag.v[:, RIGHT_SHOULDER], 'qd14': bag.v[:, LEFT_SHOULDER],
        'qd8': bag.v[:, TORSO_YAW], 'qdd8': bag.qdd[:, TORSO_YAW],
    }
    for d in case.decompositions.values():
        p = d.name
        cols[f'{p}.valid'] = d.valid
        for name, x in d.terms().items():
            cols[f'{p}.{name}'] = x
        cols[f'{p}.sum_M_ij_qdd_j'] = -d.m_total
        cols[f'{p}.m_total_minus_g'] = d.m_total - d.gravity
        cols[f'{p}.residual_rel'] = d.residual_rel
        for source, x in d.tau_by_source.items():
            cols[f'{p}.tau[{source}]'] = x
        cols[f'{p}.passive'] = d.passive
        for j, x in d.coupling_series().items():
            cols[f'{p}.M[{p},{j}]*qdd[{j}]'] = x
    return cols
