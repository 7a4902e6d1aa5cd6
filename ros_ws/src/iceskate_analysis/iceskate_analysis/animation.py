"""A run seen from the side (world y to the right, z up; right side red, left blue): a
stick-figure GIF and a key-frame strip (PNG), drawn from forward kinematics of the recorded q
in each sample's support model.
"""

from __future__ import annotations

from collections.abc import Callable
import pathlib
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from iceskate_sim.errors import InputRefused
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import LINK_NAMES, Robot
from iceskate_sim.progress import ProgressBar

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.lines import Line2D
    from matplotlib.text import Text

    from iceskate_analysis.bag_io import BagData

__all__ = ['SEGMENTS', 'frame_indices', 'link_positions', 'render_gif', 'render_keyframes']

#: Points of the stick figure: the anatomical link frames, the head top and the sole corners.
POINTS = (*LINK_NAMES, 'head_top', 'right_heel', 'right_toe', 'left_heel', 'left_toe')
_TORSO = (('pelvis', 'torso_middle'), ('torso_middle', 'chest'), ('chest', 'head'),
          ('head', 'head_top'))


def _limb(side: str) -> tuple[tuple[str, str], ...]:
    return ((('pelvis', f'{side}_thigh'), (f'{side}_thigh', f'{side}_shank'),
             (f'{side}_shank', f'{side}_foot'), (f'{side}_foot', f'{side}_heel'),
             (f'{side}_heel', f'{side}_toe'), (f'{side}_toe', f'{side}_foot'),
             ('chest', f'{side}_upper_arm'), (f'{side}_upper_arm', f'{side}_forearm'),
             (f'{side}_forearm', f'{side}_hand')))


#: (colour, segments) of the stick figure.
SEGMENTS = (('k', _TORSO), ('tab:red', _limb('right')), ('tab:blue', _limb('left')))
_GROUND_SPACING = 0.25  # m between ground ticks (they show the travel)


def frame_indices(n: int, max_frames: int) -> np.ndarray:
    """At most ``max_frames`` sample indices spread evenly over ``n`` samples."""
    if n <= 0:
        raise InputRefused('the bag has no samples to draw')
    count = max(1, min(n, int(max_frames)))
    return np.unique(np.linspace(0, n - 1, count).round().astype(int))


def link_positions(bag: BagData, robot: Robot, indices: np.ndarray) -> dict[str, np.ndarray]:
    """World positions [m] of every point of POINTS at the samples ``indices``.

    :return: point name -> (len(indices), 3) array.
    """
    out = {name: np.zeros((len(indices), 3)) for name in POINTS}
    data: dict[tuple[str, str], pin.Data] = {}
    for row, k in enumerate(indices):
        side, pivot = bag.side_name(k), bag.pivot_name(k)
        sm = robot.support_model(side, pivot)
        d = data.setdefault((side, pivot), sm.model.createData())
        pin.framesForwardKinematics(sm.model, d, bag.q[k])
        for name in POINTS:
            frame = name
            if name.endswith(('_heel', '_toe')):  # sole corners: support or swing foot
                foot_side, corner = name.split('_')
                frame = f'{"support" if foot_side == side else "swing"}_{corner}'
            out[name][row] = d.oMf[sm.frame_ids[frame]].translation
    return out


def _caption(bag: BagData, k: int) -> str:
    mode = get_mode(int(bag.mode[k]))
    pivot = '' if int(bag.pivot[k]) == 0 else f', {bag.pivot_name(k)} pivot'
    return (f't = {bag.t[k]:.3f} s   step {int(bag.step_index[k]) + 1}\n'
            f'mode {mode.number} ({mode.support}/{mode.swing})\n'
            f'support {bag.side_name(k)}{pivot}')


class _Stick:
    """The artists of one stick figure on one axes, updated in place.

    The view follows the robot: the horizontal axis is y relative to the pelvis, so the axes
    stay fixed and the ground ticks (every 0.25 m of world y) show the travel.
    """

    def __init__(self, ax: Axes, half_width: float, fontsize: float = 8.0,
                 caption_in_title: bool = False, animated: bool = False) -> None:
        self.ax = ax
        self.caption_in_title = caption_in_title
        self.lines: list[tuple[tuple[str, str], Line2D]] = []
        for colour, segments in SEGMENTS:
            for segment in segments:
                (line,) = ax.plot([], [], color=colour, lw=2.0, solid_capstyle='round',
                                  animated=animated)
                self.lines.append((segment, line))
        (self.head,) = ax.plot([], [], 'o', color='k', ms=7, mfc='w', animated=animated)
        (self.ticks,) = ax.plot([], [], '|', color='0.5', ms=6, animated=animated)
        ax.axhline(0.0, color='0.4', lw=1.0)
        ax.set_aspect('equal')
        ax.set_xlim(-half_width, half_width)
        ax.set_ylim(-0.1, 1.9)
        ax.set_xlabel('y − y_pelvis [m]', fontsize=fontsize)
        ax.tick_params(labelsize=fontsize - 1)
        self.half_width = half_width
        self.text: Text | None = None
        if not caption_in_title:
            self.text = ax.text(0.02, 0.98, '', transform=ax.transAxes, va='top',
                                fontsize=fontsize, family='monospace', animated=animated)
        self.fontsize = fontsize

    @property
    def artists(self) -> list[Artist]:
        """The artists that change from frame to frame."""
        moving: list[Artist] = [line for _, line in self.lines]
        moving += [self.head, self.ticks]
        if self.text is not None:
            moving.append(self.text)
        return moving

    def update(self, points: dict[str, np.ndarray], row: int, caption: str) -> None:
        """Draw sample ``row`` of ``points``."""
        centre = float(points['pelvis'][row, 1])
        for (a, b), line in self.lines:
            line.set_data([points[a][row, 1] - centre, points[b][row, 1] - centre],
                          [points[a][row, 2], points[b][row, 2]])
        head = 0.4 * points['head'][row] + 0.6 * points['head_top'][row]
        self.head.set_data([head[1] - centre], [head[2]])
        lo, hi = centre - self.half_width, centre + self.half_width
        ticks = np.arange(np.floor(lo / _GROUND_SPACING), np.ceil(hi / _GROUND_SPACING) + 1)
        self.ticks.set_data(ticks * _GROUND_SPACING - centre, np.zeros_like(ticks))
        caption = f'{caption}\ny_pelvis = {centre:.2f} m'
        if self.text is not None:
            self.text.set_text(caption)
        else:
            self.ax.set_title(caption, fontsize=self.fontsize, family='monospace', loc='left')


def render_gif(bag: BagData, robot: Robot, path: str | pathlib.Path, max_frames: int = 120,
               fps: float = 20.0, progress: bool = False,
               check: Callable[[], None] | None = None) -> pathlib.Path:
    """Write a stick-figure GIF of the run (``max_frames`` frames spread over the run);
    ``check`` is called before each frame (it may raise to end the drawing, the file then
    partly written)."""
    import imageio.v2 as imageio
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    indices = frame_indices(bag.n_samples, max_frames)
    points = link_positions(bag, robot, indices)
    fig = Figure(figsize=(5.0, 4.6), dpi=90)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.1, top=0.94)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.set_title(f'{bag.scene_name or bag.path.name}: side view (right red, left blue)',
                 fontsize=9)
    stick = _Stick(ax, half_width=0.9, animated=True)
    canvas.draw()  # the static part once (axes, labels, floor); frames are blitted on it
    background = canvas.copy_from_bbox(fig.bbox)
    bar = ProgressBar(indices.size, 'animation', 'frame', progress, leave=False)
    try:
        with imageio.get_writer(path, mode='I', duration=1000.0 / fps, loop=0) as writer:
            for row, k in enumerate(indices):
                if check is not None:
                    check()
                stick.update(points, row, _caption(bag, int(k)))
                canvas.restore_region(background)
                for artist in stick.artists:
                    ax.draw_artist(artist)
                writer.append_data(np.asarray(canvas.buffer_rgba())[..., :3].copy())
                bar.update(1)
    finally:
        bar.close()
    return path


def render_keyframes(bag: BagData, robot: Robot, path: str | pathlib.Path, count: int = 8,
                     ) -> pathlib.Path:
    """Write a strip of ``count`` key frames spread evenly over the run as one PNG."""
    from matplotlib.figure import Figure
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    indices = frame_indices(bag.n_samples, count)
    points = link_positions(bag, robot, indices)
    fig = Figure(figsize=(2.4 * indices.size, 4.0), layout='constrained')
    axes = fig.subplots(1, indices.size, squeeze=False)[0]
    for row, (ax, k) in enumerate(zip(axes, indices, strict=True)):
        stick = _Stick(ax, half_width=0.6, fontsize=6.0, caption_in_title=True)
        stick.update(points, row, _caption(bag, int(k)))
        if row:
            ax.set_yticklabels([])
    fig.suptitle(f'{bag.scene_name or bag.path.name}: key frames (side view, right red, '
                 'left blue)', fontsize=9)
    fig.savefig(path, dpi=100)
    return path
