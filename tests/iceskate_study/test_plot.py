"""Heat maps of a sweep's table (a table filled without running anything)."""

import matplotlib.image
import numpy as np
import pytest

from iceskate_sim.run.metrics import METRICS
from iceskate_study.errors import StudyError
from iceskate_study.plot import _ordered, cell_text, draw_maps, main, map_figure, metric_label
from iceskate_study.spec import expand, parse_spec
from iceskate_study.table import RESULTS, ResultTable, read_table


@pytest.fixture
def table(tmp_path, grid):
    """A results table of the 2 x 2 grid with made-up metrics; one run failed, one fell; a
    correlation of -0.997 in the first cell."""
    grid['metrics'] = ['steps', 'fell', 'arm_swing', 'arm_swing_steady']
    grid['ratios'] = {'arm_swing_ratio': {
        'metric': ['arm_swing.mean_peak_to_peak'],
        'baseline': {'inputs.gait_manager.yaw.amplitude': 0.0}}}
    spec = parse_spec(grid, tmp_path / 'spec.yaml')
    points = expand(spec)
    results = ResultTable(tmp_path, spec, points)
    for i, point in enumerate(points):
        row = {'key': point.key, 'status': 'ok', 'steps': 10 + i, 'fell': i == 2,
               'arm_swing': None, 'arm_swing.mean_peak_to_peak': 0.1 * (i + 1),
               'arm_swing_steady': None, 'arm_swing_steady.q11_peak_to_peak': 0.1 * (i + 1),
               'arm_swing_steady.corr_q11_q14': (-0.997, -0.5, 0.25)[i % 3]}
        if i == 3:
            row = {'key': point.key, 'status': 'failed', 'failure': 'it broke'}
        results.add(point, row)
    results.write()
    return tmp_path / RESULTS


def test_the_table_holds_the_ratio_against_its_baseline(table):
    """The ratio over the run without yaw at the same friction; none where a run fell or
    failed."""
    rows = read_table(table)[0].to_pylist()
    assert [r['arm_swing_ratio'] for r in rows] == [pytest.approx(1.0), pytest.approx(2.0),
                                                    None, None]
    assert read_table(table)[1]['ratios']['arm_swing_ratio']['baseline'] == {
        'inputs.gait_manager.yaw.amplitude': 0.0}


def test_a_heat_map_is_written_and_not_empty(table, tmp_path):
    written = draw_maps(table, 'inputs.gait_manager.yaw.amplitude', 'floor.mu',
                        ['steps', 'fell', 'arm_swing_ratio', 'arm_swing_steady.corr_q11_q14'],
                        tmp_path / 'maps')
    assert [p.name for p in written] == ['steps.png', 'fell.png', 'arm_swing_ratio.png',
                                         'arm_swing_steady.corr_q11_q14.png']
    for path in written:
        image = matplotlib.image.imread(path)
        assert image.shape[0] > 300 and image.shape[1] > 400
        assert np.std(image[..., :3]) > 0.05  # drawn, not blank


def test_sweep_plot_draws_the_default_maps_and_refuses_bad_names(table, capsys):
    assert main([str(table.parent)]) == 0
    printed = capsys.readouterr().out.split()
    assert [p.rsplit('/', 1)[1] for p in printed] == [
        'steps.png', 'fell.png', 'arm_swing_ratio.png', 'arm_swing_steady.corr_q11_q14.png']
    assert main([str(table.parent), '--metric', 'speed']) == 2
    assert capsys.readouterr().err.startswith("sweep-plot: error: --metric 'speed' is not a "
                                              'column of')
    assert main([str(table.parent), '--x', 'duration']) == 2
    assert "--x 'duration' is not an axis" in capsys.readouterr().err
    with pytest.raises(StudyError, match='cannot read the results table'):
        draw_maps(table.parent / 'other.parquet', 'a', 'b', ['steps'], table.parent)


def test_a_vector_valued_axis_is_drawn_one_column_per_vector(tmp_path, grid):
    """An axis whose values are lists (a gain vector) gives one column per distinct vector,
    in the order of their entries."""
    grid['axes'] = {'inputs.visual_lifting.kp': [[40, 290, 1100], [30, 290, 1100]],
                    'floor.mu': [0.005, 0.01]}
    grid['metrics'] = ['steps']
    spec = parse_spec(grid, tmp_path / 'spec.yaml')
    points = expand(spec)
    results = ResultTable(tmp_path, spec, points)
    for i, point in enumerate(points):
        results.add(point, {'key': point.key, 'status': 'ok', 'steps': i})
    results.write()
    written = draw_maps(tmp_path / RESULTS, 'inputs.visual_lifting.kp', 'floor.mu', ['steps'],
                        tmp_path / 'maps')
    assert [p.name for p in written] == ['steps.png']
    assert np.std(matplotlib.image.imread(written[0])[..., :3]) > 0.05
    assert _ordered([[40, 2], None, [30, 2], [40, 2], [30, 1]]) == [[30, 1], [30, 2], [40, 2]]


def test_map_axes_are_labelled_with_unit_and_meaning_from_the_schema():
    from iceskate_study.plot import axis_label
    assert axis_label('inputs.gait_manager.yaw.amplitude') == (
        'inputs.gait_manager.yaw.amplitude [N m]\nA of eq. (10)')
    assert axis_label('floor.mu').startswith('floor.mu [-]\nCoulomb coefficient')
    assert axis_label('duration') == 'duration [s]\nrun length'
    assert axis_label('disturbances[0].force[1]') == 'disturbances[0].force[1]'  # no schema


X, Y = 'inputs.gait_manager.yaw.amplitude', 'floor.mu'


def _drawn(fig):
    """The renderer of ``fig`` once laid out and drawn."""
    fig.canvas.draw()
    return fig.canvas.get_renderer()


@pytest.mark.parametrize('metric', ['steps', 'arm_swing_ratio', 'arm_swing_steady.corr_q11_q14'])
def test_every_label_of_a_map_lies_inside_the_saved_image(table, tmp_path, metric):
    fig = map_figure(*read_table(table), X, Y, metric)
    renderer = _drawn(fig)
    ax, bar = fig.axes
    inside = fig.bbox.padded(-2)  # [px] nothing touches the edge either
    labels = [ax.xaxis.label, ax.yaxis.label, ax.title, bar.yaxis.label]
    ticks = [t for a in (ax.xaxis, ax.yaxis, bar.yaxis) for t in a.get_ticklabels()
             if t.get_text() and a.get_view_interval().min() <= a.convert_units(t.get_position()[
                 a is not ax.xaxis]) <= a.get_view_interval().max()]
    assert len(ticks) >= 4
    for text in labels + ticks:
        box = text.get_window_extent(renderer)
        assert box.width > 0 and inside.contains(box.x0, box.y0) and inside.contains(
            box.x1, box.y1), f'{text.get_text()!r} at {box} outside {inside}'
    assert fig.bbox_inches.contains(*fig.get_tightbbox(renderer).min) and \
        fig.bbox_inches.contains(*fig.get_tightbbox(renderer).max)  # [inch] all artists
    path = draw_maps(table, X, Y, [metric], tmp_path / 'maps')[0]  # the image is the figure
    assert matplotlib.image.imread(path).shape[:2] == (round(fig.bbox.height),
                                                       round(fig.bbox.width))


def test_the_colour_bar_names_the_metric_and_its_unit(table):
    """First line: the column and its unit; second: its meaning, from the metrics' registry."""
    for metric, unit in (('arm_swing_ratio', '×'), ('arm_swing_steady.q11_peak_to_peak', 'rad'),
                         ('arm_swing_steady.corr_q11_q14', '-'), ('steps', '-')):
        fig = map_figure(*read_table(table), X, Y, metric)
        assert fig.axes[1].get_ylabel() == f'{metric} [{unit}]\n{METRICS[metric].label}'
    for metric, unit in (('head_error_rms.y', 'm'), ('head_error_rms.pitch', 'rad'),
                         ('forward_distance_m', 'm'), ('sim_time_s', 's'),
                         ('arm_swing.corr_q11_q14', '-')):
        assert metric_label(metric).split('\n') == [f'{metric} [{unit}]', METRICS[metric].label]
    assert metric_label('speed_ratio', ratios={'speed_ratio': {}}) == (
        'speed_ratio [×]\nratio against the baseline run')  # a ratio the SPEC names
    assert metric_label('score') == 'score'  # nothing known


def test_cells_show_three_significant_digits_and_never_round_to_a_whole_number(table):
    assert [cell_text(v) for v in (-0.997, 0.5, 10.0, 10.5, 0.33333, -0.9996, 999.96,
                                   1234.5, 0.0)] == [
        '-0.997', '0.5', '10', '10.5', '0.333', '-0.9996', '999.96', '1234.5', '0']
    fig = map_figure(*read_table(table), X, Y, 'arm_swing_steady.corr_q11_q14')
    renderer = _drawn(fig)
    ax = fig.axes[0]
    assert sorted(t.get_text() for t in ax.texts) == ['-0.5', '-0.997', '0.25', 'failed']
    cell = ax.get_window_extent(renderer).width / 2  # [px] 2 columns
    assert all(t.get_window_extent(renderer).width < cell for t in ax.texts)


def test_cell_values_shrink_to_fit_narrow_cells(tmp_path, grid):
    grid['axes'] = {'floor.mu': {'linspace': [0.001, 0.02, 20]}, X: [0.0, 10.0]}
    grid['metrics'] = ['arm_swing_steady']
    spec = parse_spec(grid, tmp_path / 'spec.yaml')
    points = expand(spec)
    results = ResultTable(tmp_path, spec, points)
    for i, point in enumerate(points):
        results.add(point, {'key': point.key, 'status': 'ok',
                            'arm_swing_steady.corr_q11_q14': -0.99996 + i * 1e-6})
    results.write()
    fig = map_figure(*read_table(tmp_path / RESULTS), 'floor.mu', X,
                     'arm_swing_steady.corr_q11_q14')
    renderer = _drawn(fig)
    ax = fig.axes[0]
    assert len(ax.texts) == 40 and all(len(t.get_text()) >= 7 for t in ax.texts)
    cell = ax.get_window_extent(renderer).width / 20  # [px]
    assert max(t.get_window_extent(renderer).width for t in ax.texts) < cell
