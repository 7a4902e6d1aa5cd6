"""Heat maps of a sweep's table (a table filled without running anything)."""

import matplotlib.image
import numpy as np
import pytest

from iceskate_study.errors import StudyError
from iceskate_study.plot import _ordered, draw_maps, main
from iceskate_study.spec import expand, parse_spec
from iceskate_study.table import RESULTS, ResultTable, read_table


@pytest.fixture
def table(tmp_path, grid):
    """A results table of the 2 x 2 grid with made-up metrics; one run failed, one fell."""
    grid['metrics'] = ['steps', 'fell', 'arm_swing_steady']
    grid['ratios'] = {'arm_swing_ratio': {
        'metric': ['arm_swing_steady.q11_peak_to_peak'],
        'baseline': {'inputs.gait_manager.yaw.amplitude': 0.0}}}
    spec = parse_spec(grid, tmp_path / 'spec.yaml')
    points = expand(spec)
    results = ResultTable(tmp_path, spec, points)
    for i, point in enumerate(points):
        row = {'key': point.key, 'status': 'ok', 'steps': 10 + i, 'fell': i == 2,
               'arm_swing_steady': None, 'arm_swing_steady.q11_peak_to_peak': 0.1 * (i + 1),
               'arm_swing_steady.corr_q11_q14': -0.5}
        if i == 3:
            row = {'key': point.key, 'status': 'failed', 'failure': 'it broke'}
        results.add(point, row)
    results.write()
    return tmp_path / RESULTS


def test_the_table_holds_the_ratio_against_its_baseline(table):
    rows = read_table(table)[0].to_pylist()
    assert [r['arm_swing_ratio'] for r in rows] == [pytest.approx(1.0), pytest.approx(2.0),
                                                    pytest.approx(1.0), None]
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
    assert main([str(table.parent), '--metric', 'speed']) == 1
    assert capsys.readouterr().err.startswith("sweep-plot: error: --metric 'speed' is not a "
                                              'column of')
    assert main([str(table.parent), '--x', 'duration']) == 1
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
