"""The FBX step's bpy.log is clean: no NumPy ABI traceback from bpy's audio module (issue 28)."""
from __future__ import annotations

import pytest

from twinkit_export.fbx import BPY_NUMPY_NOTE, clean_log

from conftest import HAS_BPY


@pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) is not installed")
def test_fbx_log_has_no_traceback(fbx_out):
    log = (fbx_out.parent / "bpy.log").read_text()
    assert fbx_out.stat().st_size > 0
    assert "Traceback" not in log and "A module that was compiled" not in log, log[:2000]
    assert "Warning" not in log, log[:2000]
    assert "Unable to initialise audio" not in log
    assert BPY_NUMPY_NOTE.strip() in log


NOISE = """
A module that was compiled using NumPy 1.x cannot be run in
NumPy 2.4.6 as it may crash. To support both 1.x and 2.x
versions of NumPy, modules must be compiled with NumPy 2.0.

Traceback (most recent call last):  File "<string>", line 1, in <module>
Traceback (most recent call last):
  File "numpy/core/_multiarray_umath.py", line 46, in __getattr__
    raise ImportError(msg)
ImportError: 
A module that was compiled using NumPy 1.x cannot be run in
NumPy 2.4.6 as it may crash.


Unable to initialise audio
ImportError: numpy.core.multiarray failed to import
"""


def test_only_the_known_block_is_removed(tmp_path):
    log = tmp_path / "bpy.log"
    other = "Traceback (most recent call last):\n  File \"x.py\", line 1\nValueError: a real failure\n"
    log.write_text(NOISE + "FBX export starting...\n" + other)
    clean_log(log)
    text = log.read_text()
    assert "A module that was compiled" not in text and "Unable to initialise audio" not in text
    assert text.startswith(BPY_NUMPY_NOTE) and other in text and "FBX export starting" in text
    # a log without the block is left alone
    log.write_text(other)
    clean_log(log)
    assert log.read_text() == other
