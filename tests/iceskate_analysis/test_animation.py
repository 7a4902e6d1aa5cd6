"""Forward kinematics of the recorded q, the stick-figure GIF and the key-frame strip."""

from __future__ import annotations

import numpy as np
import pytest

from iceskate_analysis.animation import (
    POINTS,
    frame_indices,
    link_positions,
    render_gif,
    render_keyframes,
)
from iceskate_analysis.bag_io import read_bag
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import SOLE_HEEL_Y, load_robot


@pytest.fixture(scope='module')
def synthetic(synthetic_bag):
    return read_bag(synthetic_bag)


def test_link_positions_put_the_flat_support_sole_on_the_floor(synthetic):
    robot = load_robot()
    flat = np.flatnonzero(~synthetic.active[:, 1])  # q1 locked: the support sole is flat
    points = link_positions(synthetic, robot, flat)
    assert set(points) == set(POINTS)
    for row, k in enumerate(flat):
        side = synthetic.side_name(k)
        for corner in ('heel', 'toe'):
            assert points[f'{side}_{corner}'][row, 2] == pytest.approx(0.0, abs=1e-12)
        assert points[f'{side}_heel'][row, 1] == pytest.approx(
            synthetic.q[k, 0] + SOLE_HEEL_Y, abs=1e-12)
        assert 1.5 < points['head_top'][row, 2] < 1.75
    # the head pose recorded by the run is the head_top frame
    np.testing.assert_allclose(points['head_top'], synthetic.head_position[flat], atol=1e-12)


def test_frame_indices_spread_over_the_run():
    assert frame_indices(100, 5).tolist() == [0, 25, 50, 74, 99]
    assert frame_indices(3, 10).tolist() == [0, 1, 2]
    with pytest.raises(SimulationError, match='no samples'):
        frame_indices(0, 5)


def test_gif_and_key_frames_are_written(tmp_path, synthetic):
    from PIL import Image
    robot = load_robot()
    gif = render_gif(synthetic, robot, tmp_path / 'run.gif', max_frames=6)
    with Image.open(gif) as image:
        assert image.format == 'GIF'
        assert image.n_frames == 6
    strip = render_keyframes(synthetic, robot, tmp_path / 'strip.png', count=4)
    with Image.open(strip) as image:
        assert image.format == 'PNG'
        assert image.width > 2 * image.height
