"""The paper's eq. (11) at one joint, evaluated on a recorded run (no re-simulation), and the
arm swing of both shoulders. The terms, their signs and the closure check are those of
docs/model.md §13; the interval-averaged accelerations are described in docs/usage.md.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
import csv
from dataclasses import dataclass, field, replace
import hashlib
import os
import pathlib
import stat
import tempfile
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from iceskate_analysis.bag_io import BLOCK, PASSIVE, BagData, BagReading
from iceskate_analysis.rows import join_rows, sample_count, take_rows
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.model.dynamics import ContactState, DynamicsParameters, ModelTerms
from iceskate_sim.model.modes import MULTIPLIER_NAMES, get_mode
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, Q1, Y0, Robot, load_robot
from iceskate_sim.progress import ProgressBar
from iceskate_sim.run.metrics import (
    ARM_SWING_FROM_STEP,
    LEFT_SHOULDER,
    RIGHT_SHOULDER,
    TORSO_YAW,
    shoulder_correlation,
)
from iceskate_sim.shutdown import raise_if_stopped

if TYPE_CHECKING:
    from iceskate_sim.shutdown import StopRequest

__all__ = ['ArmSwing', 'CaseResult', 'FIGURE_ROWS', 'JointDecomposition', 'RIGHT_SHOULDER',
           'LEFT_SHOULDER', 'TERMS', 'analyse_bag', 'analyse_case', 'arm_swing', 'decompose',
           'dynamics_for_bag', 'mirror_joint', 'parse_joint', 'robot_for_bag', 'write_csv']

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

    :raises InputRefused: for anything that is not one of the 18 coordinates.
    """
    text = str(value).strip()
    if text in COORDINATE_NAMES:
        return COORDINATE_NAMES.index(text)
    try:
        index = int(text)
    except ValueError:
        index = -1
    if not 0 <= index < N_COORDINATES:
        raise InputRefused(f'unknown joint {value!r}: give 0..17 or one of '
                           f'{list(COORDINATE_NAMES)} ({RIGHT_SHOULDER} = right shoulder, '
                           f'{LEFT_SHOULDER} = left)')
    return index


def mirror_joint(joint: int) -> int | None:
    """The other arm's shoulder for a shoulder (q11 <-> q14), else None."""
    return {RIGHT_SHOULDER: LEFT_SHOULDER, LEFT_SHOULDER: RIGHT_SHOULDER}.get(joint)


# ------------------------------------------------------------------------- the model of a bag
def _private_cache() -> pathlib.Path:
    """This user's folder for files made from bags (``$TMPDIR/iceskate-<uid>``, mode 0700):
    a file there is trusted by its name, so no other user may write into it.

    :raises SimulationError: when the folder is a link, another user's or open to others.
    """
    folder = pathlib.Path(tempfile.gettempdir()) / f'iceskate-{os.getuid()}'
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        info = folder.lstat()
    except OSError as exc:
        raise SimulationError(f'cannot use {folder}: {exc.strerror or exc}') from None
    if (not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid()
            or info.st_mode & 0o077):
        raise SimulationError(f'{folder} is not a folder of this user alone (a link, another '
                              "user's, or open to others): the bag's URDF is not written there")
    return folder


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
    path = _private_cache() / f'bag_urdf_{digest}.urdf'
    if not path.is_file():  # whole or not at all: a later run trusts the file by its name
        with tempfile.NamedTemporaryFile('w', encoding='utf-8', dir=path.parent,
                                         prefix=f'.{path.stem}.', delete=False) as staged:
            staged.write(bag.urdf)
        os.replace(staged.name, path)
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

    def period_averaged(self, accelerations: np.ndarray, defined: np.ndarray
                        ) -> JointDecomposition:
        """The row with ``accelerations`` (N, 18), e.g. ``interval_accelerations``, in place of
        the recorded q̈ in M_ii q̈_i and M_total; valid only where they are ``defined``."""
        valid = self.valid & defined
        own, coupling = _inertia_terms(self.mass_row, accelerations, valid, self.joint)
        return replace(self, valid=valid, own_inertia=own, coupling=coupling)


def _inertia_terms(mass_row: np.ndarray, accelerations: np.ndarray, valid: np.ndarray,
                   joint: int) -> tuple[np.ndarray, np.ndarray]:
    """M_ii q̈_i (N,) and M_ij q̈_j with column i zeroed (N, 18) [N m] of ``accelerations``
    (N, 18), nan where not ``valid``."""
    terms = np.where(valid[:, None], mass_row * accelerations, np.nan)
    own = terms[:, joint].copy()
    terms[:, joint] = np.where(valid, 0.0, np.nan)
    return own, terms


def interval_accelerations(bag: BagData, following: BagData | None = None
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The accelerations the integrator produced over each sampling interval,
    (v_{k+1} - v_k) / (t_{k+1} - t_k) (N, 18) [m/s², rad/s²], and where they are defined (N,):
    no transition in (t_k, t_{k+1}] (no impact and no re-rooted coordinates in between, also
    none that went out and back between two samples of a thinned bag) and the same mode,
    support side, pivot and step at both ends; at the last sample only with ``following``, the
    block of samples after ``bag``."""
    n = bag.n_samples
    if following is not None and following.n_samples:
        bag = join_rows([bag, take_rows(following, slice(0, 1))])
    out = np.full((bag.n_samples, N_COORDINATES), np.nan)
    defined = np.zeros(bag.n_samples, dtype=bool)
    if bag.n_samples >= 2:
        same = ((bag.mode[1:] == bag.mode[:-1]) & (bag.side[1:] == bag.side[:-1])
                & (bag.pivot[1:] == bag.pivot[:-1])
                & (bag.step_index[1:] == bag.step_index[:-1])
                & (bag.last_transition_ns[1:] <= bag.t_ns[:-1]))
        dt = np.diff(bag.t)[:, None]
        out[:-1] = np.where(same[:, None], (bag.v[1:] - bag.v[:-1]) / dt, np.nan)
        defined[:-1] = same
    return out[:n], defined[:n]


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
              dynamics: ModelTerms | None = None, progress: bool | ProgressBar = False,
              ) -> dict[int, JointDecomposition]:
    """Evaluate eq. (11) at each of ``joints`` for every sample of ``bag``.

    :param joints: coordinate indices (0 = y0, 1..17 = q1..q17).
    :param dynamics: the model to use (default: :func:`dynamics_for_bag`).
    :param progress: show a tqdm progress bar (or advance this one).
    :return: joint -> its decomposition.
    :raises InputRefused: for an unknown joint or a sample the model cannot evaluate.
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
    bar = (progress if isinstance(progress, ProgressBar)
           else ProgressBar(n, f'eq. (11) {bag.path.name}', 'sample', progress, leave=False))
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
                raise InputRefused(f'{bag.path}: cannot evaluate the model at t = '
                                   f'{bag.t[k]:.6f} s (mode {mode.number}): {exc}') from exc
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
        if bar is not progress:
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
    :ivar correlation: corr(q11, q14) over the window, ``shoulder_correlation`` (the
        registry's ``arm_swing.corr_q11_q14``: raw, −1: mirror images).
    :ivar phase_difference_deg: phase of q11 relative to q14 from the Hilbert transform of the
        detrended angles (amplitude-weighted mean over the window), in (−180, 180]; ±180 is
        anti-phase.
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


def analysis_window(step_index: np.ndarray) -> tuple[np.ndarray, int | None]:
    """Mask of the samples from ``step_index >= ARM_SWING_FROM_STEP`` on (and that step), or
    all (and None) when too few."""
    mask = step_index >= ARM_SWING_FROM_STEP
    if int(mask.sum()) >= MIN_WINDOW:
        return mask, ARM_SWING_FROM_STEP
    return np.ones(step_index.size, dtype=bool), None


def _dominant_frequency(t: np.ndarray, x: np.ndarray) -> float:
    if x.size < 4 or not np.any(x != x[0]):
        return float('nan')
    dt = float(np.mean(np.diff(t)))
    spectrum = np.abs(np.fft.rfft(x - x.mean()))
    freqs = np.fft.rfftfreq(x.size, dt)
    return float(freqs[1:][np.argmax(spectrum[1:])]) if freqs.size > 1 else float('nan')


def arm_swing(t: np.ndarray, right: np.ndarray, left: np.ndarray, step_index: np.ndarray
              ) -> ArmSwing:
    """Peak-to-peak, frequency, correlation (``shoulder_correlation``, as ``metrics.json``'s)
    and phase (of the linearly detrended angles, which the Hilbert transform needs) of q11
    (``right`` [rad]) versus q14 (``left``) over the samples at times ``t`` [s] of
    ``analysis_window(step_index)``."""
    from scipy.signal import detrend, hilbert
    mask, step = analysis_window(step_index)
    t, right, left = t[mask], right[mask], left[mask]
    p2p = {'q11': float(np.ptp(right)) if right.size else float('nan'),
           'q14': float(np.ptp(left)) if left.size else float('nan')}
    freq = {'q11': _dominant_frequency(t, right), 'q14': _dominant_frequency(t, left)}
    correlation, phase = shoulder_correlation(right, left), float('nan')
    if right.size >= 4:
        a, b = detrend(right), detrend(left)
        if np.std(a) > 0.0 and np.std(b) > 0.0:
            za, zb = hilbert(a), hilbert(b)
            phase = float(np.degrees(np.angle(np.sum(za * np.conj(zb)))))
            if phase <= -180.0:
                phase += 360.0
    return ArmSwing(step, float(t[0]) if t.size else float('nan'), int(mask.sum()), p2p, freq,
                    correlation, phase)


# ------------------------------------------------------------------------------ one case
@dataclass
class CaseResult:
    """Everything computed for one bag.

    :ivar kept: the samples drawn in the figures and the animation: all of them up to
        ``FIGURE_ROWS``, else every 2^k-th (a bag is never held whole).
    :ivar decompositions: eq. (11) at the joint and its mirror, at the kept samples.
    :ivar averaged_decompositions: the same with the interval-averaged accelerations.
    :ivar end_s: time of the run's last sample [s].
    """

    label: str
    joint: int
    kept: BagData
    decompositions: dict[int, JointDecomposition]
    averaged_decompositions: dict[int, JointDecomposition]
    arms: ArmSwing
    torso_yaw_input: bool
    fourth_step_s: float | None
    end_s: float
    rankings: dict[int, list[tuple[str, float]]] = field(repr=False)
    summary_entry: dict[str, Any] = field(repr=False)

    @property
    def main(self) -> JointDecomposition:
        """The decomposition of the chosen joint."""
        return self.decompositions[self.joint]

    def averaged(self, d: JointDecomposition) -> JointDecomposition:
        """``d``'s joint with the accelerations averaged over each sampling interval."""
        return self.averaged_decompositions[d.joint]

    def ranking(self, joint: int) -> list[tuple[str, float]]:
        """Coupling terms M_ij q̈_j at ``joint`` by decreasing RMS over the arm-swing window
        (every sample when the run is too short for one)."""
        return self.rankings[joint]

    def summary(self) -> dict[str, Any]:
        """The summary.json entry of this case."""
        return self.summary_entry


#: Most samples a case keeps for its figures and animation (``CaseResult.kept``).
FIGURE_ROWS = 1 << 13
#: The masks the sums are kept over: the arm-swing window (from the 4th step) and the whole run
#: (in place of the window when the run is too short for one, ``analysis_window``).
_MASKS = ('window', 'whole')


class _MeanSquares:
    """Sums of squares and counts of named series over their finite entries."""

    def __init__(self) -> None:
        self.sums: dict[tuple[str, ...], float] = {}
        self.counts: dict[tuple[str, ...], int] = {}

    def add(self, key: tuple[str, ...], x: np.ndarray) -> None:
        x = x[np.isfinite(x)]
        self.sums[key] = self.sums.get(key, 0.0) + float(np.dot(x, x))
        self.counts[key] = self.counts.get(key, 0) + x.size

    def rms(self, *key: str) -> float:
        n = self.counts.get(key, 0)
        return float(np.sqrt(self.sums[key] / n)) if n else float('nan')


class _Kept:
    """Every stride-th sample of a stream of blocks, at most ``limit``: the stride doubles
    (every other kept sample let go) whenever more would be kept."""

    def __init__(self, limit: int) -> None:
        self.limit, self.stride, self.count = limit, 1, 0
        self.parts: list[tuple[np.ndarray, tuple[Any, ...]]] = []  # (indices, records)

    def add(self, first: int, records: tuple[Any, ...]) -> None:
        """Keep the samples of ``records`` (of one block, whose first sample is the stream's
        ``first``) that fall on the stride."""
        rows = np.arange(-first % self.stride, sample_count(records[0]), self.stride)
        if not rows.size:
            return
        self.parts.append((first + rows, tuple(take_rows(r, rows) for r in records)))
        self.count += rows.size
        while self.count > self.limit:  # every other kept sample, as one part
            self.stride *= 2
            halves = [(indices[on], tuple(take_rows(r, on) for r in kept))
                      for indices, kept in self.parts
                      for on in [indices % self.stride == 0] if np.any(on)]
            self.parts = [(np.concatenate([h[0] for h in halves]),
                           tuple(join_rows(list(records), _missing)
                                 for records in zip(*(h[1] for h in halves), strict=True)))]
            self.count = self.parts[0][0].size

    def joined(self) -> list[Any]:
        """The kept samples of each record, as one record each."""
        return [join_rows(list(records), _missing)
                for records in zip(*(part[1] for part in self.parts), strict=True)]


def _missing(record: Any, key: str, n: int) -> np.ndarray:
    """An input of a source a block of a decomposition does not have (it came later): 0 where
    the joint is valid, else nan; an effort of a block of a bag: 0."""
    if isinstance(record, JointDecomposition):
        return _masked(np.zeros(n), ~record.valid)
    return np.zeros((n, N_COORDINATES))


class _Analysis:
    """The analysis of one run fed block by block: eq. (11) at the joints, the sums of its
    summary, the shoulders (whole: their spectrum and phase need them), the kept samples of the
    figures, and the CSV's rows (spilled to a file until its header is known)."""

    def __init__(self, joint: int, spill: _Spill | None) -> None:
        self.joint = joint
        self.joints = (joint,) + ((mirror_joint(joint),) if mirror_joint(joint) is not None
                                  else ())
        self.spill = spill
        self.dyn: ModelTerms | None = None
        self.sums = {mask: _MeanSquares() for mask in _MASKS}
        self.shoulders: list[tuple[np.ndarray, ...]] = []  # (t, q11, q14, step_index)
        self.kept = _Kept(FIGURE_ROWS)
        self.samples, self.steps, self.in_window, self.yaw = 0, 0, 0, False
        self.first_t = self.last_t = float('nan')
        self.fourth_step_s: float | None = None
        self.valid = {i: 0 for i in self.joints}
        self.averaged_valid = {i: 0 for i in self.joints}
        self.closure = {i: (0.0, 0.0) for i in self.joints}  # max relative, max absolute
        self.mass_i8 = {i: 0.0 for i in self.joints}  # sum of M_i8 over the valid samples
        self.coupled = {(i, view): np.zeros(N_COORDINATES, dtype=bool)
                        for i in self.joints for view in ('exact', 'averaged')}
        self.sources: list[str] = []

    def add(self, bag: BagData, following: BagData | None, progress: ProgressBar) -> None:
        """Analyse the block ``bag`` (``following``: the block after it, None at the end)."""
        if self.dyn is None:
            self.dyn = dynamics_for_bag(bag)
        exact = decompose(bag, self.joints, self.dyn, progress)
        interval = interval_accelerations(bag, following)
        averaged = {i: d.period_averaged(*interval) for i, d in exact.items()}
        self.sources = list(bag.sources)  # every source so far, in their order
        in_window = bag.step_index >= ARM_SWING_FROM_STEP
        masks = {'window': in_window, 'whole': np.ones(bag.n_samples, dtype=bool)}
        for i in self.joints:
            self._sum(exact[i], averaged[i], masks)
        t = bag.t
        self.shoulders.append((t, bag.q[:, RIGHT_SHOULDER].copy(), bag.q[:, LEFT_SHOULDER].copy(),
                               bag.step_index.copy()))
        if self.fourth_step_s is None and np.any(in_window):
            self.fourth_step_s = float(t[np.argmax(in_window)])
        if not self.samples:
            self.first_t = float(t[0])
        self.last_t = float(t[-1])
        self.steps = max(self.steps, int(bag.step_index.max()))
        self.in_window += int(in_window.sum())
        yaw = bag.efforts.get('yaw')
        self.yaw = self.yaw or bool(yaw is not None and np.any(yaw[:, TORSO_YAW] != 0.0))
        self.kept.add(self.samples, (bag, *exact.values(), *averaged.values()))
        if self.spill is not None:
            self.spill.add(_columns(bag, exact))
        self.samples += bag.n_samples

    def _sum(self, d: JointDecomposition, averaged: JointDecomposition,
             masks: dict[str, np.ndarray]) -> None:
        i, p = d.joint, d.name
        self.valid[i] += int(d.valid.sum())
        self.averaged_valid[i] += int(averaged.valid.sum())
        if np.any(d.valid):
            rel, residual = d.residual_rel[d.valid], np.abs(d.residual[d.valid])
            self.closure[i] = (float(np.maximum(self.closure[i][0], rel.max())),
                               float(np.maximum(self.closure[i][1], residual.max())))
            self.mass_i8[i] += float(np.sum(d.mass_row[d.valid, TORSO_YAW]))
        for view, x in (('exact', d), ('averaged', averaged)):
            self.coupled[(i, view)] |= np.any(x.coupling[x.valid] != 0.0, axis=0)
        terms, averaged_terms = d.terms(), averaged.terms()
        for mask_name, mask in masks.items():
            sums = self.sums[mask_name]
            exact_mask, averaged_mask = mask & d.valid, mask & averaged.valid
            for source, x in d.tau_by_source.items():
                if (p, 'tau', source) not in sums.counts:  # it came later: 0 at the valid
                    # samples of the blocks before
                    sums.counts[(p, 'tau', source)] = sums.counts.get((p, 'valid'), 0)
                    sums.sums[(p, 'tau', source)] = 0.0
                sums.add((p, 'tau', source), x[exact_mask])
            sums.counts[(p, 'valid')] = sums.counts.get((p, 'valid'), 0) + int(exact_mask.sum())
            for name, x in terms.items():
                sums.add((p, 'exact', name), x[exact_mask])
            for name, x in averaged_terms.items():
                sums.add((p, 'averaged', name), x[averaged_mask])
            sums.add((p, 'exact', 'm_total_minus_g'), (d.m_total - d.gravity)[exact_mask])
            sums.add((p, 'exact', 'sum_minus_g'), (-d.m_total - d.gravity)[exact_mask])
            sums.add((p, 'averaged', 'm_total_minus_g'),
                     (averaged.m_total - averaged.gravity)[averaged_mask])
            for view, x, m in (('exact', d, exact_mask), ('averaged', averaged, averaged_mask)):
                for j in range(N_COORDINATES):
                    if j != i:
                        sums.add((p, f'{view} coupling', COORDINATE_NAMES[j]), x.coupling[m, j])

    def result(self, label: str, notes: list[str], bag_path: pathlib.Path, scene: str
               ) -> CaseResult:
        """The case, once every block was added."""
        t, right, left, step_index = (np.concatenate(x) for x in zip(*self.shoulders, strict=True))
        arms = arm_swing(t, right, left, step_index)
        sums = self.sums['window' if arms.window_from_step is not None else 'whole']
        kept_bag, *kept = self.kept.joined()
        n = len(self.joints)
        decompositions = {d.joint: d for d in kept[:n]}
        averaged = {d.joint: d for d in kept[n:]}
        rankings = {i: self._ranking(sums, i, 'exact') for i in self.joints}
        joints = {COORDINATE_NAMES[i]: self._joint_summary(sums, i) for i in self.joints}
        main = joints[COORDINATE_NAMES[self.joint]]
        entry = {
            'bag': str(bag_path), 'scene': scene, 'samples': self.samples,
            'duration_s': self.last_t - self.first_t, 'steps': self.steps,
            'sources': self.sources,
            'torso_yaw_input': self.yaw, 'fourth_step_s': self.fourth_step_s,
            'rms_window': {'from_step_index': arms.window_from_step,
                           'start_s': arms.window_start_s,
                           'samples': self.in_window if arms.window_from_step is not None
                           else self.samples},
            'joint': COORDINATE_NAMES[self.joint],
            'closure_residual_max_rel': main['closure_residual_max_rel'],
            'closure_residual_max_abs': main['closure_residual_max_abs'],
            'arms': arms.as_dict(),
            **{key: main[key] for key in ('rms', 'rms_tau_by_source', 'rms_m_total_minus_g',
                                          'rms_sum_minus_g', 'coupling_ranking')},
            'joints': joints,
            'notes': list(notes),
        }
        return CaseResult(label, self.joint, kept_bag, decompositions, averaged, arms,
                          self.yaw, self.fourth_step_s, self.last_t, rankings, entry)

    def _ranking(self, sums: _MeanSquares, i: int, view: str) -> list[tuple[str, float]]:
        p = COORDINATE_NAMES[i]
        ranked = [(COORDINATE_NAMES[j], sums.rms(p, f'{view} coupling', COORDINATE_NAMES[j]))
                  for j in range(N_COORDINATES) if j != i and self.coupled[(i, view)][j]]
        return sorted(ranked, key=lambda item: -item[1] if np.isfinite(item[1]) else 0.0)

    def _joint_summary(self, sums: _MeanSquares, i: int) -> dict[str, Any]:
        """Closure, RMS of every term and the coupling ranking of one joint."""
        p = COORDINATE_NAMES[i]
        valid = self.valid[i]
        paper = {}
        for view, key in (('instantaneous', 'exact'), ('interval_averaged', 'averaged')):
            gravity = sums.rms(p, key, 'gravity')
            paper[f'rms_m_total_minus_g_over_rms_g_{view}'] = (
                sums.rms(p, key, 'm_total_minus_g') / gravity if gravity > 0.0
                else float('nan'))
            paper[f'rms_m_total_{view}'] = sums.rms(p, key, 'm_total')
        paper['rms_g'] = sums.rms(p, 'exact', 'gravity')
        paper['rms_h'] = sums.rms(p, 'exact', 'coriolis')
        out: dict[str, Any] = {
            'samples_valid': valid,
            'closure_residual_max_rel': self.closure[i][0] if valid else float('nan'),
            'closure_residual_max_abs': self.closure[i][1] if valid else float('nan'),
            'rms': {name: sums.rms(p, 'exact', name) for name in TERMS},
            'rms_tau_by_source': {s: sums.rms(p, 'tau', s) for s in self.sources},
            'rms_m_total_minus_g': sums.rms(p, 'exact', 'm_total_minus_g'),
            'rms_sum_minus_g': sums.rms(p, 'exact', 'sum_minus_g'),
            'coupling_ranking': [{'coordinate': name, 'rms': value}
                                 for name, value in self._ranking(sums, i, 'exact')],
            'interval_averaged': {
                'samples_valid': self.averaged_valid[i],
                'rms': {name: sums.rms(p, 'averaged', name) for name in TERMS
                        if name != 'residual'},
                'coupling_ranking': [{'coordinate': name, 'rms': value}
                                     for name, value in self._ranking(sums, i, 'averaged')],
            },
            'paper_reading': paper,
        }
        if valid:
            out['mean_M_i8'] = self.mass_i8[i] / valid
        else:
            out['note'] = f'{p} is a coordinate of none of the recorded modes'
        return out


def _with_next(blocks: Iterable[BagData]) -> Iterator[tuple[BagData, BagData | None]]:
    """Each block with the one after it (None for the last)."""
    previous = None
    for block in blocks:
        if previous is not None:
            yield previous, block
        previous = block
    if previous is not None:
        yield previous, None


def analyse_bag(reading: BagReading, label: str, joint: int = RIGHT_SHOULDER,
                csv: pathlib.Path | None = None, progress: bool = False,
                size: int = BLOCK, stop: StopRequest | None = None) -> CaseResult:
    """Read and analyse a bag block by block (``size`` samples): eq. (11) at ``joint`` (and at
    the other shoulder for a shoulder), the arm swing, and ``csv``, the CSV of every series
    (``_columns``) when given. What is held is a few blocks, the figures' samples and the
    shoulders' angles, whatever the length of the run. A stop signal (``stop``, also given
    to ``reading``) is looked for between blocks and between the blocks of the CSV.

    :raises InputRefused: on a bag that cannot be read or a sample the model cannot
        evaluate.
    :raises RunInterrupted: on a stop signal (t: the samples before it were analysed; ``csv``
        may then be partly written).
    """
    joint = parse_joint(joint)
    spill = _Spill(csv) if csv is not None else None
    try:
        analysis = _Analysis(joint, spill)
        bar = ProgressBar(reading.sample_bound, f'eq. (11) {reading.path.name}', 'sample',
                          progress, leave=False)
        try:
            for block, following in _with_next(reading.blocks(size)):
                raise_if_stopped(stop, float(block.t[0]), f'analysing bag {reading.path}')
                analysis.add(block, following, bar)
        finally:
            bar.close()
        case = analysis.result(label, reading.notes, reading.path,
                               reading.custom_data.get('scene', ''))
        if spill is not None:
            spill.write(analysis.coupled, analysis.joints, lambda: raise_if_stopped(
                stop, case.end_s, f'writing the CSV of bag {reading.path}'))
        return case
    finally:
        if spill is not None:
            spill.close()


def analyse_case(bag: BagData, label: str, joint: int = RIGHT_SHOULDER,
                 size: int = BLOCK) -> CaseResult:
    """``analyse_bag`` of a bag read whole (``read_bag``), in blocks of ``size`` samples."""
    joint = parse_joint(joint)
    analysis = _Analysis(joint, None)
    blocks = (take_rows(bag, slice(k, k + size)) for k in range(0, bag.n_samples, size))
    bar = ProgressBar(bag.n_samples, '', 'sample', False)
    for block, following in _with_next(blocks):
        analysis.add(block, following, bar)
    return analysis.result(label, list(bag.notes), bag.path, bag.scene_name)


# ---------------------------------------------------------------------------------- export
def write_csv(path: str | pathlib.Path, blocks: Iterable[dict[str, np.ndarray]],
              header: list[str] | None = None) -> pathlib.Path:
    """Write blocks of equal-length columns one after the other to a CSV file under a header
    row (default: the first block's names; nan written as 'nan'), turned into text
    ``CSV_BLOCK`` rows at a time, so that the text in memory is bounded whatever the length.

    :raises ValueError: when a block's columns differ in length.
    """
    path = pathlib.Path(path)
    with path.open('w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        if header is not None:
            writer.writerow(header)
        for columns in blocks:
            if header is None:
                header = list(columns)
                writer.writerow(header)
            arrays = [np.asarray(columns[name]) for name in header]
            lengths = {len(a) for a in arrays}
            if len(lengths) > 1:
                raise ValueError(f'columns of different lengths {sorted(lengths)} for {path}')
            for start in range(0, lengths.pop() if lengths else 0, CSV_BLOCK):
                text = [[str(int(x)) for x in part] if part.dtype.kind in 'biu'
                        else [repr(float(x)) for x in part]
                        for part in (a[start:start + CSV_BLOCK] for a in arrays)]
                writer.writerows(zip(*text, strict=True))
    return path


class _Spill:
    """The CSV's columns of each block, in a temporary file beside the CSV until its header
    (every source, every coupled coordinate of the run) is known; then the CSV, block by
    block."""

    def __init__(self, path: pathlib.Path) -> None:
        self.path = pathlib.Path(path)
        self.file = tempfile.TemporaryFile(dir=self.path.parent, prefix='.spill_')
        self.names: list[str] = []

    def add(self, columns: dict[str, np.ndarray]) -> None:
        names = self.names = list(columns)  # the last block's: every source so far
        np.save(self.file, np.array(names))
        for array in columns.values():
            np.save(self.file, np.asarray(array))

    def write(self, coupled: dict[tuple[int, str], np.ndarray], joints: tuple[int, ...],
              check: Callable[[], None]) -> pathlib.Path:
        """The CSV: a coupling column of a coordinate that never couples is left out; a column
        a block lacks (a source that came later) is 0 where its joint is valid, else nan;
        ``check`` is called before each block (it may raise to end the writing)."""
        never = {_coupling_column(i, j) for i in joints for j in range(N_COORDINATES)
                 if j != i and not coupled[(i, 'exact')][j]}
        header = [n for n in self.names if n not in never]
        end = self.file.tell()
        self.file.seek(0)

        def blocks() -> Iterator[dict[str, np.ndarray]]:
            while self.file.tell() < end:
                check()
                names = [str(n) for n in np.load(self.file)]
                block = {name: np.load(self.file) for name in names}
                yield {name: block[name] if name in block
                       else np.where(block[f'{name.split(".")[0]}.valid'], 0.0, np.nan)
                       for name in header}
        return write_csv(self.path, blocks(), header)

    def close(self) -> None:
        self.file.close()


def _coupling_column(i: int, j: int) -> str:
    p, c = COORDINATE_NAMES[i], COORDINATE_NAMES[j]
    return f'{p}.M[{p},{c}]*qdd[{c}]'


def _columns(bag: BagData, decompositions: dict[int, JointDecomposition]
             ) -> dict[str, np.ndarray]:
    """Every time series of a block: the state of both arms and the terms of every joint
    (the coupling of every other coordinate)."""
    cols: dict[str, np.ndarray] = {
        't_s': bag.t, 'mode': bag.mode, 'support_side': bag.side, 'pivot': bag.pivot,
        'step_index': bag.step_index,
        'q11': bag.q[:, RIGHT_SHOULDER], 'q14': bag.q[:, LEFT_SHOULDER],
        'qd11': bag.v[:, RIGHT_SHOULDER], 'qd14': bag.v[:, LEFT_SHOULDER],
        'qd8': bag.v[:, TORSO_YAW], 'qdd8': bag.qdd[:, TORSO_YAW],
    }
    for d in decompositions.values():
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
        for j in range(N_COORDINATES):
            if j != d.joint:
                cols[_coupling_column(d.joint, j)] = d.coupling[:, j]
    return cols
