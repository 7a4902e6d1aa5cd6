"""``coupling_analysis``: the whole analysis of a pair of bags, its figures' legends clear of
their titles and data, its refusals, and no progress bar into a pipe."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys

import pytest

from iceskate_analysis.coupling_cli import main


@pytest.fixture(scope='module')
def compared_with_figures(tmp_path_factory, synthetic_bag, synthetic_no_yaw_bag,
                          record_figures):
    """Run the CLI once: the yaw bag compared with the no-yaw bag, with the animation; its
    output folder and the figures it saved, by file name."""
    out = tmp_path_factory.mktemp('analysis')
    with record_figures() as figures:
        code = main([str(synthetic_bag), '--compare', str(synthetic_no_yaw_bag), '--out',
                     str(out), '--animate', '--frames', '5', '--quiet'])
    assert code == 0
    return out, figures


@pytest.fixture(scope='module')
def compared(compared_with_figures):
    """The output folder of ``compared_with_figures``."""
    return compared_with_figures[0]


def test_paper_figures_are_written_for_the_right_cases(compared):
    summary = json.loads((compared / 'summary.json').read_text())
    comparison = summary['comparison']
    # the yaw bag was given first; Fig. 5 is still the run without the torso-yaw input
    assert comparison['without_yaw'] == 'synthetic_no_yaw'
    assert comparison['with_yaw'] == 'synthetic_yaw'
    assert comparison['assigned_by'] == 'yaw source'
    for name in ('fig5_shoulders.png', 'fig6_shoulders.png', 'fig7_terms_q11.png',
                 'fig8_terms_q11.png', 'fig7_terms_q11_instantaneous.png',
                 'fig8_terms_q11_instantaneous.png', 'compare_shoulders.png'):
        assert (compared / name).stat().st_size > 10_000, name
    assert comparison['arm_peak_to_peak_ratio_with_over_without']['q11'] > 1.0
    for joint in ('q11', 'q14'):  # the paper's reading, in numbers, at both shoulders
        reading = comparison['paper_reading'][joint]
        for case in ('without_yaw', 'with_yaw'):
            figures = reading[case]
            assert figures['rms_g'] > 0.0 and figures['rms_h'] >= 0.0
            for view in ('instantaneous', 'interval_averaged'):
                assert figures[f'rms_m_total_minus_g_over_rms_g_{view}'] >= 0.0
        assert reading['rms_h_with_over_without'] == pytest.approx(
            reading['with_yaw']['rms_h'] / reading['without_yaw']['rms_h'])


def test_no_legend_runs_over_a_title_the_data_or_another_legend(compared_with_figures,
                                                                legends_clear):
    """Figs. 5-8 carry long titles and the terms' legend two rows: the titles sit above the
    legends, the legends above their panels."""
    _out, figures = compared_with_figures
    for name in ('fig5_shoulders.png', 'fig6_shoulders.png', 'fig7_terms_q11.png',
                 'fig8_terms_q11_instantaneous.png', 'compare_shoulders.png',
                 'synthetic_yaw_coupling_q11.png'):
        assert legends_clear(figures[name]) >= 1, name
    fig7 = figures['fig7_terms_q11.png']
    title = fig7.axes[0].get_title()
    assert title.startswith('Fig. 7: terms of eq. (11) at q11 without τ8')
    rows = {round(t.get_window_extent().y0)
            for t in fig7.axes[0].get_legend().get_texts()}
    assert len(rows) == 2  # 7 entries in rows of 6 (no soft stop or swing constraint)


def test_no_progress_bar_goes_into_a_pipe(tmp_path, synthetic_bag):
    """stderr a pipe (``coupling_analysis ... 2> log``): no bar, not even a frozen first one."""
    run = subprocess.run([sys.executable, '-m', 'iceskate_analysis.coupling_cli',
                          str(synthetic_bag), '--out', str(tmp_path)],
                         capture_output=True, text=True, timeout=240, check=False)
    assert run.returncode == 0, run.stderr
    assert run.stderr == ''
    assert (tmp_path / 'summary.json').is_file()


def test_a_terminal_gets_the_progress_bars(tmp_path, synthetic_bag):
    """stderr a terminal (a pseudo-terminal of 100 columns here): the bars are drawn there."""
    import fcntl
    import pty
    import struct
    import termios
    controller, terminal = pty.openpty()
    try:
        fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack('HHHH', 24, 100, 0, 0))
        process = subprocess.Popen([sys.executable, '-m', 'iceskate_analysis.coupling_cli',
                                    str(synthetic_bag), '--out', str(tmp_path)],
                                   stdout=subprocess.DEVNULL, stderr=terminal)
        os.close(terminal)
        seen = b''
        while True:
            try:
                chunk = os.read(controller, 4096)
            except OSError:  # EIO: the terminal's last writer has closed it
                break
            if not chunk:
                break
            seen += chunk
        assert process.wait(timeout=240) == 0
    finally:
        os.close(controller)
    assert b'reading bag' in seen and b'eq. (11) bag' in seen


def test_every_case_gets_figures_csv_and_animation(compared):
    summary = json.loads((compared / 'summary.json').read_text())
    for label in ('synthetic_yaw', 'synthetic_no_yaw'):
        files = summary['files'][label]
        assert set(files) == {f'{label}_shoulders.png', f'{label}_terms_q11.png',
                              f'{label}_terms_q11_instantaneous.png',
                              f'{label}_coupling_q11.png', f'{label}_series.csv',
                              f'{label}_animation.gif', f'{label}_keyframes.png'}
        for name in files:
            assert (compared / name).stat().st_size > 1_000, name


def test_csv_holds_every_series(compared):
    with (compared / 'synthetic_yaw_series.csv').open() as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 160
    columns = set(rows[0])
    for joint in ('q11', 'q14'):
        for term in ('own_inertia', 'tau', 'm_total', 'coriolis', 'gravity', 'damping',
                     'residual', 'residual_rel', 'm_total_minus_g', 'tau[yaw]'):
            assert f'{joint}.{term}' in columns
    assert 'q11.M[q11,q8]*qdd[q8]' in columns
    assert {'t_s', 'mode', 'step_index', 'q11', 'q14'} <= columns
    assert float(rows[-1]['t_s']) == pytest.approx(0.159)


def test_summary_has_one_entry_per_case(compared):
    summary = json.loads((compared / 'summary.json').read_text())
    assert summary['joint'] == 'q11'
    for case in summary['cases'].values():
        assert case['closure_residual_max_rel'] <= 1e-9
        for arm in ('q11', 'q14'):
            assert case['arms'][arm]['peak_to_peak_rad'] > 0.0
        assert case['arms']['phase_difference_deg'] is not None
        assert case['rms']['coriolis'] > 0.0
        assert case['rms_m_total_minus_g'] > 0.0
        assert case['coupling_ranking'][0]['rms'] >= case['coupling_ranking'][-1]['rms']


def test_the_left_shoulder_can_be_chosen(tmp_path, synthetic_bag):
    assert main([str(synthetic_bag), '--joint', '14', '--out', str(tmp_path), '--quiet']) == 0
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary['joint'] == 'q14'
    assert (tmp_path / 'synthetic_yaw_terms_q14.png').is_file()
    assert 'comparison' not in summary


def test_a_truncated_bag_is_refused_with_a_message(tmp_path, truncated_bag, capsys):
    assert main([str(truncated_bag), '--out', str(tmp_path / 'out'), '--quiet']) == 2
    assert 'truncated or corrupt' in capsys.readouterr().err


def test_a_bag_without_accelerations_is_refused(tmp_path, sim_bag, bag_without, capsys):
    broken = bag_without(sim_bag, '/joint_dynamics')
    assert main([str(broken), '--out', str(tmp_path / 'out'), '--quiet']) == 2
    err = capsys.readouterr().err
    assert 'no topic /joint_dynamics' in err and 'accelerations' in err


def test_an_unknown_joint_is_refused(tmp_path, synthetic_bag, capsys):
    assert main([str(synthetic_bag), '--joint', '21', '--out', str(tmp_path), '--quiet']) == 2
    assert 'unknown joint' in capsys.readouterr().err
