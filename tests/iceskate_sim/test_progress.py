"""The command-line tools' progress bar: a bar on a terminal only; into a pipe or a file its
notes are plain lines and nothing else is written (a log keeps no frozen bar)."""

import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios

SCRIPT = ('from iceskate_sim.progress import ProgressBar\n'
          'with ProgressBar(3, "runs", "run") as bar:\n'
          '    bar.note("3 runs on 1 worker")\n'
          '    bar.update(3)\n')


def test_into_a_pipe_only_the_notes_are_written():
    done = subprocess.run([sys.executable, '-c', SCRIPT], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0 and done.stderr == '3 runs on 1 worker\n', done.stderr


def test_on_a_terminal_the_bar_is_drawn():
    parent, child = pty.openpty()
    fcntl.ioctl(child, termios.TIOCSWINSZ, struct.pack('HHHH', 24, 100, 0, 0))  # 100 columns
    try:
        done = subprocess.run([sys.executable, '-c', SCRIPT], stderr=child,
                              stdout=subprocess.DEVNULL, timeout=60)
        os.close(child)
        child = -1
        written = b''
        while True:
            try:
                chunk = os.read(parent, 4096)
            except OSError:  # the terminal's other end is closed: all read
                break
            if not chunk:
                break
            written += chunk
    finally:
        if child >= 0:
            os.close(child)
        os.close(parent)
    assert done.returncode == 0
    assert b'3 runs on 1 worker' in written and b'3/3' in written, written
