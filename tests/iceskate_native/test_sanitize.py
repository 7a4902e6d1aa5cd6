"""The native core under AddressSanitizer and UndefinedBehaviorSanitizer (``make sanitize``).

``scripts/sanitize.sh`` builds ``iceskate_native`` with ``-fsanitize=address,undefined`` in its
own colcon bases (``ros_ws/build-sanitize``, ``install-sanitize``), runs ``tests/iceskate_native``
(not the ``slow`` ones) and the whole ``skate`` scene with that module, and exits non-zero on any
sanitizer report. On 2 cores, alone, a fresh clone's run takes about 360 s (276 s of build at
-O1 with an empty ccache, 88 s of tests and scene); a warm ccache saves most of the build.
"""

import os
from pathlib import Path
import signal
import subprocess

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
SCRIPT = REPO_ROOT / 'scripts' / 'sanitize.sh'
#: Deadline of the whole script, against a hang: five times the ~360 s of a fresh clone alone.
DEADLINE_S = 1800


def _compiler_has_asan() -> bool:
    try:
        path = subprocess.run(['g++', '-print-file-name=libasan.so'], capture_output=True,
                              text=True, check=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return False
    return os.path.isabs(path) and os.path.isfile(path)  # else g++ echoes the bare name


@pytest.mark.slow
@pytest.mark.timeout(DEADLINE_S + 60)
def test_the_native_core_is_clean_under_asan_and_ubsan(tmp_path):
    if not _compiler_has_asan():
        pytest.skip('g++ with libasan is needed for the sanitized build')
    env = dict(os.environ, ICESKATE_SANITIZE_OUT=str(tmp_path))
    # Its own process group, so that on the deadline colcon and the compilers go too.
    process = subprocess.Popen(['bash', str(SCRIPT)], cwd=REPO_ROOT, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               start_new_session=True)
    try:
        output, _ = process.communicate(timeout=DEADLINE_S)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        output, _ = process.communicate()
        pytest.fail(f'scripts/sanitize.sh took more than {DEADLINE_S} s:\n{output[-5000:]}')
    assert process.returncode == 0, (
        f'scripts/sanitize.sh exited {process.returncode}:\n{output[-20000:]}')
    assert '[sanitize] OK: no sanitizer report' in output, output[-5000:]
