"""The paper's figures are written as non-empty, decodable PNG files; legends clear of titles,
data and each other however many rows they take; the compared runs on one angle scale."""

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


def test_compared_shoulders_share_one_angle_scale(tmp_path, cases, saved_figures):
    """The runs' arms swing 0.05 and 0.3 rad: both panels still span the same angles."""
    plots.plot_compare_shoulders(cases, tmp_path / 'compare.png')
    fig = saved_figures['compare.png']
    top, bottom = fig.axes
    assert top.get_ylim() == bottom.get_ylim()
    low, high = top.get_ylim()
    assert high - low > 2 * 17.0  # the larger swing, ±0.3 rad
    assert [top.get_title(), bottom.get_title()] == [
        'no_yaw (without torso-yaw input τ8)', 'yaw (with torso-yaw input τ8)']


@pytest.mark.parametrize('ncol', [1, 2, 6])
def test_a_legend_of_many_rows_stays_between_its_title_and_its_axes(tmp_path, legends_clear,
                                                                     ncol):
    fig, (ax, below) = plots._figure(2)
    for k in range(6):
        ax.plot([0, 1], [k, -k], label=f'line {k} with a label q̈_{k} Σ M_{k},j')
        below.plot([0, 1], [k, k], label=f'below {k}')
    plots.legend_above(ax, ncol=ncol, title='A long title ' * 8)
    plots.legend_above(below, ncol=ncol)
    assert legends_clear(fig) == 2
    rows = {round(t.get_window_extent().y0) for t in ax.get_legend().get_texts()}
    assert len(rows) == -(-6 // ncol) if ncol < 6 else len(rows) > 1  # 6 too wide for a row
    assert ax.title.get_window_extent().y0 >= ax.get_legend().get_window_extent().y1


def test_a_title_without_a_legend_sits_where_matplotlib_puts_it(tmp_path):
    from matplotlib import rcParams
    fig, (ax,) = plots._figure(1)
    ax.plot([0, 1], [0, 1])
    plots.legend_above(ax, title='no labelled line')
    assert ax.get_legend() is None and ax.get_title() == 'no labelled line'
    fig.canvas.draw()
    gap = ax.title.get_window_extent().y0 - ax.get_window_extent().y1  # pixels
    assert 0.0 < gap < rcParams['axes.titlepad'] * fig.dpi / 72.0
