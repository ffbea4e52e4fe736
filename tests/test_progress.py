"""Progress output: bars on a terminal only."""
from __future__ import annotations

import os
import pty
import subprocess
import sys

from tests.conftest import ROOT

CODE = """
import time
from twinkit.progress import step_status, track
with step_status('03_reconstruct (reconstructor/poisson)'):
    for i in track(range(3), desc='items'):
        time.sleep(0.3)
print('DONE')
"""


def test_quiet_when_not_a_terminal():
    p = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0 and p.stdout.strip() == "DONE" and p.stderr == ""


def test_live_display_on_a_terminal():
    pid, fd = pty.fork()
    if pid == 0:  # child: stdout/stderr are the pseudo-terminal
        os.chdir(ROOT)
        os.execv(sys.executable, [sys.executable, "-c", CODE])
    out = b""
    while True:
        try:
            chunk = os.read(fd, 4096)
        except OSError:
            break
        if not chunk:
            break
        out += chunk
    os.waitpid(pid, 0)
    text = out.decode(errors="replace")
    assert "DONE" in text
    assert "03_reconstruct" in text and "items" in text
