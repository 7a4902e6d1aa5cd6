"""The paper's figures are written as non-empty, decodable PNG files."""

from __future__ import annotations

import pytest

from iceskate_analysis import plots
from iceskate_analysis.bag_io import read_bag
from iceskate_analysis.coupling import analyse_case


@pytest.fixture(scope='module')
def cases(synthetic_bag, synthetic_no_yaw_bag):
    return [analyse_case(read_bag(synthetic_no_yaw_bag), 'no_yaw', 11),
            analyse_case(read_bag(synthetic_bag), 'yaw', 11)]


def _assert_png(path, min_width=400):
    from PIL import Image
    assert path.is_file() and path.stat().st_size > 10_000, f'{path} missing or tiny'
    with Image.open(path) as image:
        assert image.format == 'PNG'
        assert image.width >= min_width
        # not a blank canvas: many distinct colours
        assert len(image.convert('RGB').getcolors(maxcolors=1_000_000)) > 20


def test_shoulder_figures(tmp_path, cases):
    for case in cases:
        _assert_png(plots.plot_shoulders(case, tmp_path / f'{case.label}.png', 'Fig. 5'))
    _assert_png(plots.plot_compare_shoulders(cases, tmp_path / 'compare.png'))


@pytest.mark.parametrize('joint', [11, 14])
def test_term_figures(tmp_path, cases, joint):
    path = plots.plot_terms(cases[1], tmp_path / f'terms_{joint}.png', joint=joint)
    _assert_png(path)


def test_coupling_figure(tmp_path, cases):
    _assert_png(plots.plot_coupling(cases[1], tmp_path / 'coupling.png', top=4))
