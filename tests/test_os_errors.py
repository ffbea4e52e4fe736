"""twinkit.os_errors: an operating-system error becomes one line naming the cause and the path, with the
exit status of whose problem it is (an unreadable input: 2; a full disk: the step failed, 1)."""
from __future__ import annotations

import errno
import sqlite3

import pytest

from twinkit.errors import InputError, StepError
from twinkit.os_errors import explaining_os_errors, os_error_in, os_text


def _raise(exc: BaseException):
    def run():
        raise exc
    return run


def test_unreadable_file_is_the_inputs_problem(tmp_path):
    f = tmp_path / "cloud.las"
    with pytest.raises(InputError) as info:
        explaining_os_errors(_raise(PermissionError(errno.EACCES, "Permission denied", str(f))), tmp_path)
    assert str(info.value) == f"{f}: permission denied; make it readable (and writable for outputs) by this user"
    assert info.value.exit_code == 2


def test_full_disk_is_a_failed_step_and_names_the_free_space(tmp_path):
    with pytest.raises(StepError) as info:
        explaining_os_errors(_raise(OSError(errno.ENOSPC, "No space left on device")), tmp_path / "a" / "b")
    text = str(info.value)
    assert text.startswith(f"disk full (no space left on the device) writing {tmp_path / 'a' / 'b'} (")
    assert "MiB free" in text and "twinkit gc" in text and info.value.exit_code == 1


def test_sqlite_full_database_is_a_full_disk(tmp_path):
    exc = sqlite3.OperationalError("database or disk is full")
    assert os_error_in(exc) is not None and os_error_in(exc).errno == errno.ENOSPC
    with pytest.raises(StepError, match="disk full"):
        explaining_os_errors(_raise(exc), tmp_path)


def test_a_steps_os_error_keeps_the_step_in_the_message(tmp_path):
    cause = OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "x.ply"))
    step = StepError("step 'mesh' failed: boom")
    step.__cause__ = cause
    with pytest.raises(StepError) as info:
        explaining_os_errors(_raise(step), tmp_path)
    assert str(info.value) == f"step 'mesh' failed: {os_text(cause, tmp_path)}"
    assert info.value.__cause__ is cause


def test_other_errors_pass_unchanged(tmp_path):
    with pytest.raises(ValueError, match="nothing to do with the disk"):
        explaining_os_errors(_raise(ValueError("nothing to do with the disk")), tmp_path)
    assert explaining_os_errors(lambda: 7, tmp_path) == 7
    assert os_text(OSError(errno.EIO, "I/O error", "/x"), tmp_path) == "/x: I/O error"
