"""Bad paths and bad files are refused before anything starts, in one sentence naming the path or
key and the problem (never a traceback, never a Python method); YAML 1.2 numbers everywhere."""

import json
import os
from pathlib import Path
import re
import subprocess
import sys

import pytest
import yaml

from hostile import alias_bomb, deep
from iceskate_bringup.runner import main
from iceskate_bringup.scene import load_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.yaml_io import read_yaml

TINY = Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'
PYTHON_METHOD = re.compile(r'\w\(\)')


def _refused(capsys, argv: list[str]) -> str:
    """run_scene with ``argv`` exits 2 (refused) with one error line; that line."""
    assert main([*argv, '--quiet']) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('run_scene: error: '), err
    assert 'Traceback' not in err and not PYTHON_METHOD.search(err), err
    return lines[0]


def _scene(tmp_path: Path, **changes) -> Path:
    raw = read_yaml(TINY, 'scene') | changes
    path = tmp_path / 'scene.yaml'
    path.write_text(yaml.safe_dump(raw))
    return path


# ------------------------------------------------------------------------------ paths
@pytest.mark.parametrize('ros', [False, True], ids=['headless', 'ros'])
@pytest.mark.parametrize('case', ['existing file', 'under a file', 'cannot be created'])
def test_a_bad_out_is_refused_naming_it(tmp_path, capsys, case, ros):
    blocker = tmp_path / 'a_file'
    blocker.write_text('not a folder')
    out, expected = {
        'existing file': (blocker, f'output directory {blocker} is an existing file'),
        'under a file': (blocker / 'run', f'output directory {blocker / "run"} lies under '
                         f'{blocker}, which is an existing file'),
        'cannot be created': (Path('/sys/iceskate-test-out'),
                              'output directory /sys/iceskate-test-out cannot be created: '),
    }[case]
    line = _refused(capsys, [str(TINY), '--out', str(out), *(['--ros'] if ros else [])])
    assert expected in line, line
    assert blocker.read_text() == 'not a folder'


@pytest.mark.parametrize('ros', [False, True], ids=['headless', 'ros'])
@pytest.mark.parametrize('content', ['user files', 'a link out'])
def test_an_out_holding_files_the_run_did_not_make_is_refused(tmp_path, capsys, ros, content):
    """A run writes only files it makes: a folder holding the user's events.json and
    trajectory.npz, or a link named like an output that points outside, is refused in one line
    and nothing in it, or behind the link, is written."""
    out = tmp_path / 'out'
    out.mkdir()
    outside = tmp_path / 'outside.npz'
    outside.write_bytes(b'the user data')
    if content == 'user files':
        (out / 'events.json').write_text('mine')
        (out / 'trajectory.npz').write_bytes(b'mine too')
        held = 'events.json'
    else:
        (out / 'trajectory.npz').symlink_to(outside)
        held = 'trajectory.npz'
    line = _refused(capsys, [str(TINY), '--out', str(out), *(['--ros'] if ros else [])])
    assert line == (f"run_scene: error: output directory {out} is not empty (it holds "
                    f"{held!r}{' and more' if content == 'user files' else ''}): a run writes "
                    'only into a new or empty directory; choose another output directory')
    assert outside.read_bytes() == b'the user data'
    assert sorted(p.name for p in out.iterdir()) == sorted(  # not even a lock file
        ['events.json', 'trajectory.npz'] if content == 'user files' else ['trajectory.npz'])
    if content == 'user files':
        assert (out / 'events.json').read_text() == 'mine'


@pytest.mark.parametrize('where', ['base', 'argument'])
def test_a_file_that_is_no_yaml_is_never_read_as_a_scene(tmp_path, capsys, where):
    """`base:` (or the scene argument) naming a file that is not a .yaml, here one of secrets
    whose lines would read as keys, is refused without a word of its content."""
    secret = tmp_path / 'shadow'
    secret.write_text('root:$6$s3cr3t$hash:19000:0:99999:7:::\n')
    scene = tmp_path / 'scene.yaml'
    scene.write_text(f'base: {secret}\n')
    line = _refused(capsys, [str(scene if where == 'base' else secret), '--out',
                             str(tmp_path / 'out')])
    assert line == (f"run_scene: error: scene '{secret}' is neither a shipped scene name nor "
                    'the path of a .yaml file')
    assert 's3cr3t' not in line and not (tmp_path / 'out').exists()


def test_an_out_that_is_not_writable_is_refused(tmp_path, capsys):
    if os.geteuid() == 0:
        pytest.skip('root writes into a read-only folder (the /sys case covers it)')
    locked = tmp_path / 'locked'
    locked.mkdir(mode=0o500)
    line = _refused(capsys, [str(TINY), '--out', str(locked / 'run')])
    assert f'output directory {locked / "run"} cannot be created: permission denied' in line


@pytest.mark.parametrize('ros', [False, True], ids=['headless', 'ros'])
def test_an_out_holding_a_recorded_run_is_refused(tmp_path, capsys, ros):
    (tmp_path / 'bag').mkdir()
    line = _refused(capsys, [str(TINY), '--out', str(tmp_path), *(['--ros'] if ros else [])])
    assert f'already holds a recorded run: {tmp_path / "bag"} already exists' in line


@pytest.mark.parametrize('ros', [False, True], ids=['headless', 'ros'])
def test_an_out_holding_a_finished_run_without_a_bag_is_refused(tmp_path, capsys, ros):
    """A run recorded with record.bag: false is never overwritten by the next run."""
    scene = _scene(tmp_path, record={'bag': False})
    out = tmp_path / 'run'
    assert main([str(scene), '--out', str(out), '--quiet']) == 0
    capsys.readouterr()
    before = (out / 'metrics.json').read_bytes()
    line = _refused(capsys, [str(scene), '--out', str(out), *(['--ros'] if ros else [])])
    assert f'already holds a recorded run: {out / "metrics.json"} already exists' in line
    assert (out / 'metrics.json').read_bytes() == before


@pytest.mark.parametrize('ros', [False, True], ids=['headless', 'ros'])
def test_an_out_another_run_writes_into_is_refused(tmp_path, capsys, ros):
    """The lock of a run in progress (another process's) refuses a second run there before it
    writes anything."""
    out = tmp_path / 'run'
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, '-c', 'import sys, time\n'
         'from iceskate_sim.run.session import prepare_output\n'
         'prepare_output(sys.argv[1]); print("held", flush=True); time.sleep(60)', str(out)],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == 'held'
        line = _refused(capsys, [str(TINY), '--out', str(out), *(['--ros'] if ros else [])])
        assert f'output directory {out} is in use by another run' in line
        assert sorted(p.name for p in out.iterdir()) == ['.run.lock']
    finally:
        holder.kill()
        holder.wait(timeout=10)


def test_a_launcher_hands_its_lock_to_the_process_it_starts(tmp_path):
    """The simulator started by ``run_scene --ros`` takes the folder with the launcher's lock
    (an inherited descriptor named by ICESKATE_OUTPUT_LOCK_FD); any other process is refused."""
    from iceskate_sim.run.session import LOCK_FD_ENV, prepare_output, release_output
    out = tmp_path / 'run'
    fd = prepare_output(out)
    child = ('import sys\nfrom iceskate_sim.errors import SimulationError\n'
             'from iceskate_sim.run.session import prepare_output\n'
             'try:\n    prepare_output(sys.argv[1]); print("taken")\n'
             'except SimulationError as exc:\n    print(exc)')
    try:
        for env, fds, expected in (({LOCK_FD_ENV: str(fd)}, (fd,), 'taken'),
                                   ({}, (), 'is in use by another run'),
                                   ({LOCK_FD_ENV: '999'}, (), 'is in use by another run')):
            done = subprocess.run([sys.executable, '-c', child, str(out)], pass_fds=fds,
                                  env={**os.environ, **env}, capture_output=True, text=True,
                                  timeout=60)
            assert expected in done.stdout, done.stdout + done.stderr
    finally:
        release_output(out)
    done = subprocess.run([sys.executable, '-c', child, str(out)], capture_output=True,
                          text=True, timeout=60)
    assert done.stdout.strip() == 'taken', done.stdout + done.stderr


# ------------------------------------------------------------------------------ files
def test_a_key_given_twice_is_refused_naming_its_line(tmp_path, capsys):
    scene = tmp_path / 'twice.yaml'
    scene.write_text(TINY.read_text() + 'duration: 5.0\n')
    line = _refused(capsys, [str(scene), '--out', str(tmp_path / 'out')])
    assert f'malformed YAML in scene {scene} at line' in line
    assert "the key 'duration' is given twice" in line


@pytest.mark.parametrize('kind', ['fifo', 'device', 'directory'])
def test_a_scene_that_is_no_regular_file_is_refused_at_once(tmp_path, capsys, kind):
    """A FIFO would block the read forever and /dev/zero would fill the memory."""
    scene = tmp_path / 'scene.yaml'
    if kind == 'fifo':
        os.mkfifo(scene)
    elif kind == 'device':
        scene.symlink_to('/dev/zero')
    else:
        scene.mkdir()
    line = _refused(capsys, [str(scene), '--out', str(tmp_path / 'out')])
    what = {'fifo': 'a named pipe (FIFO)', 'device': 'a character device',
            'directory': 'a directory'}[kind]
    assert f'scene {scene} is {what}, not a regular file, and is not read' in line


def test_a_scene_larger_than_the_limit_is_refused_before_it_is_read(tmp_path, capsys):
    from iceskate_sim.yaml_io import MAX_YAML_BYTES
    scene = _scene(tmp_path, description='x' * MAX_YAML_BYTES)
    line = _refused(capsys, [str(scene), '--out', str(tmp_path / 'out')])
    assert f'scene {scene} is {scene.stat().st_size} bytes, more than the {MAX_YAML_BYTES}' in line


@pytest.mark.timeout(30)
@pytest.mark.parametrize(('value', 'problem'), [
    (alias_bomb(), 'expands to more than 100000 values (its aliases counted as what they stand '
                   'for)'),
    (deep(), 'nests mappings and sequences deeper than 64 levels'),
    ('&a [1, *a]', 'holds a value with an alias of itself inside (*a)'),
    ('[' + ', '.join(['&a0 [' + deep(30)[1:-1] + ']'] + [f'&a{k} [*a{k - 1}]'
                                                          for k in range(1, 40)]) + ']',
     'nests mappings and sequences deeper than 64 levels')])
def test_an_alias_bomb_or_a_deep_nest_in_a_scene_is_refused_small_and_fast(
        tmp_path, value, problem):
    """In a known key of a scene file (description) or of --set (floor.mu), run_scene refuses
    in one line, in seconds, no RecursionError, within 1.5 GB of address space (an expanded
    bomb would take gigabytes); aliases count as what they stand for, in values and in depth,
    and a value may not hold itself."""
    import resource
    import time

    def small() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))

    scene = _scene(tmp_path)
    scene.write_text(scene.read_text().replace('description:', f'description: {value}\nx_:', 1))
    for arguments, expected in (([str(scene)], f'scene {scene} {problem}'),
                                ([str(TINY), '--set', f'floor.mu={value}'],
                                 f'--set floor.mu {problem}')):
        start = time.monotonic()
        done = subprocess.run([sys.executable, '-m', 'iceskate_bringup.runner', *arguments,
                               '--out', str(tmp_path / 'out'), '--quiet'], capture_output=True,
                              text=True, timeout=60, preexec_fn=small)
        assert time.monotonic() - start < 20.0
        assert done.returncode == 2 and done.stderr == f'run_scene: error: {expected}\n', (
            done.stderr[-2000:])
    assert not (tmp_path / 'out').exists()


def test_aliases_within_the_bounds_still_read(tmp_path):
    (tmp_path / 'ok.yaml').write_text('a: &x [1, 2]\nb: *x\nc: ' + deep(60) + '\n')
    assert read_yaml(tmp_path / 'ok.yaml', 'scene')['b'] == [1, 2]


def test_a_binary_scene_is_refused(tmp_path, capsys):
    scene = tmp_path / 'binary.yaml'
    scene.write_bytes(bytes(range(256)) * 4)
    line = _refused(capsys, [str(scene), '--out', str(tmp_path / 'out')])
    assert f'scene {scene} is not UTF-8 text' in line
    assert not (tmp_path / 'out').exists()


def test_scene_numbers_follow_yaml_1_2(tmp_path):
    """Exponents without a dot or a sign (1e-6, 5E-3) are numbers, as in YAML 1.2."""
    path = _scene(tmp_path, integrator={'method': 'rk4', 'step': 1e-3, 'rtol': 1e-6,
                                        'atol': 1e-9})
    text = path.read_text().replace('1.0e-06', '1e-6').replace('1.0e-09', '1E-9')
    text = text.replace('0.001', '1e-3')
    assert '1e-6' in text and '1E-9' in text
    path.write_text(text)
    scene = load_scene(path)
    assert scene.simulator.integrator.rtol == 1e-6 and scene.simulator.integrator.atol == 1e-9
    assert scene.simulator.integrator.step == 1e-3


def test_a_string_where_a_number_belongs_is_still_refused(tmp_path):
    path = _scene(tmp_path)
    path.write_text(path.read_text().replace('duration: 0.03', "duration: '1e-6'"))
    with pytest.raises(SimulationError, match="scene key 'duration': must be a number"):
        load_scene(path)


@pytest.mark.parametrize('value', ['inf', 'nan', '1e9', '3600.5', '-1', '0'])
def test_duration_obeys_the_scene_limits(tmp_path, capsys, value):
    line = _refused(capsys, [str(TINY), '--out', str(tmp_path / 'out'), '--duration', value])
    assert '--duration must be > 0 and <= 3600 s' in line
    assert not (tmp_path / 'out').exists()


def test_a_coordinate_the_initial_mode_lacks_is_refused_naming_the_key(tmp_path, capsys):
    scene = _scene(tmp_path, initial={'mode': 1, 'q': {'q1': 1.5}})
    line = _refused(capsys, [str(scene), '--out', str(tmp_path / 'out')])
    assert "scene key 'initial.q.q1': q1" in line and 'not a coordinate of mode 1' in line
    scene = _scene(tmp_path, initial={'mode': 1, 'v': {'q1': 0.5}})
    line = _refused(capsys, [str(scene), '--out', str(tmp_path / 'out')])
    assert "scene key 'initial.v.q1'" in line


@pytest.mark.parametrize('ros', [False, True], ids=['headless', 'ros'])
def test_an_impossible_initial_posture_is_one_sentence(tmp_path, capsys, ros):
    """Refused before anything starts, the nodes of --ros included (no parameter files)."""
    scene = _scene(tmp_path, initial={'mode': 1, 'q': {'q5': 0.05, 'q6': -0.3, 'q7': -0.6}})
    line = _refused(capsys, [str(scene), '--out', str(tmp_path / 'out'),
                             *(['--ros'] if ros else [])])
    assert not (tmp_path / 'out' / 'params').exists()
    assert line == ("run_scene: error: scene 'tiny_stand': the initial state cannot be "
                    'simulated, it ends the run at once from mode 1 (toe-first touchdown of the '
                    "swing foot (not representable in the paper's model)); change "
                    'initial.posture, initial.q, initial.v or initial.mode')


@pytest.mark.parametrize('ros', [False, True], ids=['headless', 'ros'])
def test_a_posture_the_first_command_lifts_off_the_floor_is_no_fall(tmp_path, capsys, ros):
    """A posture that stands until the controllers' first command lifts the support foot (at
    t = 0) is an error naming the initial state, not a fall; the outputs say so."""
    if ros:
        pytest.importorskip('rclpy')
    scene = _scene(tmp_path, initial={'mode': 1, 'q': {'q5': -0.5}})
    out = tmp_path / 'out'
    assert main([str(scene), '--out', str(out), '--quiet', *(['--ros'] if ros else [])]) == 1
    err = capsys.readouterr().err
    assert 'Traceback' not in err and 'Warning' not in err, err
    (line,) = [line for line in err.splitlines() if 'error' in line]
    assert line.startswith('run_scene: error: ') and line.endswith(
        "scene 'tiny_stand': the initial state cannot be simulated under the controllers' "
        'first command, it ends the run at once from mode 1 (flight: the support foot left '
        "the floor with the swing foot in the air (not representable in the paper's model)); "
        'change initial.posture, initial.q, initial.v or initial.mode'), line
    metrics = json.loads((out / 'metrics.json').read_text())
    assert metrics['end'] == 'failed' and not metrics['fell'] and metrics['sim_time_s'] == 0.0


@pytest.mark.ros
@pytest.mark.parametrize('content, expected', [
    (bytes(range(256)), 'is not UTF-8 text'),
    (b'simulator:\n  ros__parameters: {control_timeout: [1.0\n', 'malformed YAML'),
    (f'simulator:\n  ros__parameters: {{x: {deep()}}}\n'.encode(),
     'nests mappings and sequences deeper than 64 levels'),
    (f'simulator:\n  ros__parameters: {{x: {alias_bomb()}}}\n'.encode(),
     'expands to more than 100000 values'),
])
def test_a_bad_node_parameter_file_is_refused_in_one_line(tmp_path, ros_env, content, expected):
    pytest.importorskip('rclpy')
    params = tmp_path / 'params.yaml'
    params.write_bytes(content)
    result = subprocess.run([sys.executable, '-m', 'iceskate_sim.ros.simulator_node', '--ros-args',
                             '--params-file', str(params)], env=ros_env, capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith('simulator: error: ') and f'parameter file {params}' in line, line
    assert expected in line


@pytest.mark.ros
def test_node_parameter_files_take_yaml_1_2_exponents(tmp_path, ros_env):
    """rcl reads 2e0 as a double like our reader: the node gets past its parameters (and stops
    at the missing scene, naming it)."""
    pytest.importorskip('rclpy')
    params = tmp_path / 'params.yaml'
    params.write_text('simulator:\n  ros__parameters:\n    control_timeout: 2e0\n'
                      f'    scene: {tmp_path / "missing.yaml"}\n')
    assert read_yaml(params, 'parameter file')['simulator']['ros__parameters'][
        'control_timeout'] == 2.0
    result = subprocess.run([sys.executable, '-m', 'iceskate_sim.ros.simulator_node', '--ros-args',
                             '--params-file', str(params)], env=ros_env, capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip().endswith(f'cannot read scene {tmp_path / "missing.yaml"}: '
                                          'No such file or directory'), result.stderr


@pytest.mark.ros
def test_a_controller_named_without_its_sources_gets_one_source_named_like_it(tmp_path,
                                                                             ros_env):
    """``controllers:=[..., my_ctrl]`` without ``sources.my_ctrl``: my_ctrl answers as its one
    source (the documented default); with nobody running it, the run ends naming it, its bag
    closed and readable."""
    pytest.importorskip('rclpy')
    from rosbags.highlevel import AnyReader
    out = tmp_path / 'out'
    scene = Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'
    result = subprocess.run(
        [sys.executable, '-m', 'iceskate_sim.ros.simulator_node', '--ros-args',
         '-p', f'scene:={scene}', '-p', f'out_dir:={out}', '-p', f'record_bag:={out / "bag"}',
         '-p', 'controllers:=[my_ctrl]', '-p', 'startup_timeout:=1.0'],
        env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result.stderr
    assert "controller node(s) ['my_ctrl'] not up within 1.0 s" in result.stderr, result.stderr
    assert 'Traceback' not in result.stderr
    with AnyReader([out / 'bag']) as reader:
        assert {c.topic for c in reader.connections} >= {'/robot_description', '/gait_state'}


NODE_MODULES = {'simulator': 'iceskate_sim.ros.simulator_node',
                'visual_lifting': 'visual_lifting.visual_lifting_node',
                'gait_manager': 'gait_manager.gait_manager_node',
                'plugin_controller': 'iceskate_bringup.plugin_node'}
#: The other console executables, by name: their modules (``python -m`` runs them).
CONSOLE_MODULES = {'run_scene': 'iceskate_bringup.runner', 'sweep': 'iceskate_study.sweep',
                   'sweep-plot': 'iceskate_study.plot', 'summary': 'iceskate_analysis.summary',
                   'mode_coverage': 'iceskate_analysis.coverage_cli',
                   'coupling_analysis': 'iceskate_analysis.coupling_cli',
                   'replay': 'iceskate_analysis.replay', 'view': 'iceskate_viewer.replay'}
#: Those that need rclpy.
ROS_EXECUTABLES = {*NODE_MODULES, 'replay'}


@pytest.mark.parametrize(('name', 'arguments'), [
    ('run_scene', ['{missing}.yaml', '--out', '{out}']),
    ('run_scene', ['stand', '--out', '{out}', '--duration', '-1']),
    ('sweep', ['{missing}.yaml', '--out', '{out}']),
    ('sweep', ['arm_swing', '--out', '{out}', '--workers', '0']),
    ('sweep-plot', ['{missing}']),
    ('summary', ['{missing}']),
    ('mode_coverage', ['{missing}', '--out', '{out}']),
    ('coupling_analysis', ['{missing}', '--out', '{out}']),
    ('coupling_analysis', ['{missing}', '--out', '{out}', '--frames', '0']),
    ('view', ['{missing}', '--port', '0']),
    ('view', ['{missing}', '--port', '70000']),
    pytest.param('replay', ['{missing}'], marks=pytest.mark.ros),
    pytest.param('simulator', ['--ros-args', '-p', 'scene:={missing}.yaml'],
                 marks=pytest.mark.ros),
    pytest.param('simulator', ['--ros-args', '-p', 'control_timeout:=-1.0'],
                 marks=pytest.mark.ros),
    pytest.param('visual_lifting', ['--ros-args', '--params-file', '{missing}.yaml'],
                 marks=pytest.mark.ros),
    pytest.param('gait_manager', ['--ros-args', '-p', 'posture.stiffness:=-5.0'],
                 marks=pytest.mark.ros),
    pytest.param('plugin_controller', ['--ros-args', '-p', 'plugin:=missing.module:Class'],
                 marks=pytest.mark.ros),
])
def test_every_executable_refuses_bad_input_with_exit_status_2(tmp_path, ros_env, name,
                                                              arguments):
    """The one exit-status convention (docs/usage.md, 'Exit status'): an input that does not
    exist or a bad value is refused before anything runs, with exit status 2 and one line
    ``NAME: error: ...``, no traceback, nothing written."""
    if name in ROS_EXECUTABLES:
        pytest.importorskip('rclpy')
    argv = [a.format(missing=tmp_path / 'missing', out=tmp_path / 'out') for a in arguments]
    result = subprocess.run(
        [sys.executable, '-m', NODE_MODULES.get(name) or CONSOLE_MODULES[name], *argv],
        env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    (line,) = result.stderr.splitlines()
    assert line.startswith(f'{name}: error: ') and not PYTHON_METHOD.search(line), line
    assert not list((tmp_path / 'out').rglob('*'))  # coupling_analysis makes it, empty


@pytest.mark.ros
@pytest.mark.parametrize(('name', 'parameter'), [
    ('simulator', 'startup_timeout'), ('visual_lifting', 'kp'),
    ('gait_manager', 'posture.stiffness'), ('plugin_controller', 'plugin')])
def test_help_prints_the_usage_and_the_parameters_and_starts_nothing(ros_env, name, parameter):
    result = subprocess.run([sys.executable, '-m', NODE_MODULES[name], '--help'], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f'usage: {name} [-h] [--ros-args')
    assert f'\n  {parameter} = ' in result.stdout, result.stdout
    assert result.stderr == ''  # no node came up: nothing logged


@pytest.mark.ros
def test_the_simulator_alone_runs_the_shipped_skate_and_says_whom_it_waits_for(ros_env):
    """No parameter at all: the shipped ``skate`` scene (by name); the simulator says once
    which controller nodes it waits for, then ends naming the missing ones."""
    pytest.importorskip('rclpy')
    result = subprocess.run([sys.executable, '-m', NODE_MODULES['simulator'], '--ros-args',
                             '-p', 'startup_timeout:=1.0'], env=ros_env, capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 1, result.stderr
    waiting = [line for line in result.stderr.splitlines() if 'waiting up to' in line]
    assert len(waiting) == 1
    assert "waiting up to 1 s for the controller node(s) ['gait_manager', 'visual_lifting']" \
        in waiting[0]
    assert ("controller node(s) ['gait_manager', 'visual_lifting'] not up within 1.0 s"
            in result.stderr), result.stderr


@pytest.mark.ros
def test_the_nodes_by_hand_run_a_shipped_scene_and_end_with_it(tmp_path, ros_env):
    """The simulator (a shipped scene by name, nothing else given) and both controllers
    started by hand: the simulator logs each arrival, takes each node's sources from its first
    command, runs and exits; the controllers then end by themselves with exit code 0."""
    pytest.importorskip('rclpy')
    out = tmp_path / 'out'
    simulator = subprocess.Popen(
        [sys.executable, '-m', NODE_MODULES['simulator'], '--ros-args', '-p', 'scene:=stand',
         '-p', 'duration:=0.05', '-p', f'out_dir:={out}', '-p', 'startup_timeout:=30.0'],
        env=ros_env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    nodes = {name: subprocess.Popen([sys.executable, '-m', NODE_MODULES[name]], env=ros_env,
                                    stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
             for name in ('visual_lifting', 'gait_manager')}
    logs = {}
    try:
        _, simulator_log = simulator.communicate(timeout=60)
        for name, process in nodes.items():
            logs[name] = process.communicate(timeout=30)[1]
    finally:
        for process in (simulator, *nodes.values()):
            if process.poll() is None:
                process.kill()
                process.wait(timeout=10)
    assert simulator.returncode == 0, simulator_log
    assert 'rejected' not in simulator_log, simulator_log
    for name, process in nodes.items():
        assert f'controller node {name!r} is up' in simulator_log
        assert process.returncode == 0, logs[name]
        assert 'ready: answering gait_state' in logs[name]
        assert 'the simulator is gone: the run is over' in logs[name]
    # gait_manager by hand runs its own parameters (every source), not the scene's block
    metrics = json.loads((out / 'metrics.json').read_text())
    assert metrics['sources'] == ['visual_lifting', 'posture', 'feedforward', 'weight_transfer',
                                  'heel', 'arm_assist', 'yaw']
