"""scripts/run_tests.py (what `make test` runs): the static checks are sessions that fail the run."""
from __future__ import annotations

import importlib.util
import sys

from tests.conftest import ROOT


def _run_tests_module():
    spec = importlib.util.spec_from_file_location("twinkit_run_tests", ROOT / "scripts" / "run_tests.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_ruff_and_mypy_run_first():
    assert [name for name, _ in _run_tests_module().CHECKS] == ["ruff", "mypy"]


def test_a_failed_check_is_a_failed_session_with_its_output(monkeypatch, capsys):
    mod = _run_tests_module()
    monkeypatch.setattr(mod, "CHECKS", [
        ("good", ["-c", "print('all fine')"]),
        ("bad", ["-c", "import sys; print('x.py:1: error: broken'); sys.exit(1)"]),
    ])
    assert mod.run_checks() == ["bad"]
    out = capsys.readouterr().out
    assert "===== bad =====" in out and "x.py:1: error: broken" in out and "all fine" in out
    assert mod.PY == sys.executable
