"""Shared fixtures: a throw-away configuration folder and a runner for the real ``twinkit`` command."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import pytest


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"


def needs_shared(*parts: str):
    """Skip unless ../shared (real data and weights) has the given path."""
    path = SHARED.joinpath(*parts)
    return pytest.mark.skipif(not path.exists(), reason=f"needs {path} (real sample data, not on this machine)")


@dataclass
class CliResult:
    rc: int
    out: str
    err: str

    @property
    def text(self) -> str:
        return self.out + self.err


class Project:
    """A temporary config folder (real conf/config.yaml + test sites and recipes) and an outputs folder."""

    def __init__(self, tmp: Path):
        self.conf = tmp / "conf"
        (self.conf / "site").mkdir(parents=True)
        (self.conf / "recipe").mkdir()
        shutil.copy(ROOT / "conf" / "config.yaml", self.conf / "config.yaml")
        self.out = tmp / "outputs"
        self.counter = tmp / "counter.txt"
        self.tmp = tmp
        self.site("t", "name: t\n")
        self.recipe("chain", ["{id: make, uses: step/make}", "{id: double, uses: step/double}",
                              "{id: scale, uses: step/scale}"])

    @property
    def ws(self) -> Path:
        return self.out / "t"

    def site(self, name: str, text: str) -> None:
        (self.conf / "site" / f"{name}.yaml").write_text(textwrap.dedent(text))

    def recipe(self, name: str, steps: list[str], extra: str = "") -> None:
        body = "\n".join(f"    - {s}" for s in steps)
        (self.conf / "recipe" / f"{name}.yaml").write_text(
            f"# @package _global_\n{extra}recipe:\n  name: {name}\n  steps:\n{body}\n"
        )

    def env(self, **extra: str) -> dict:
        env = dict(os.environ)
        env.update(
            TWINKIT_CONFIG_DIR=str(self.conf),
            TWINKIT_PLUGINS="builtins",
            TWINKIT_PLUGIN_MODULES="tests.support.engine_plugins",
            TWINKIT_TEST_COUNTER=str(self.counter),
            TWINKIT_RUNTIME_DIR=str(self.tmp / "runtime"),  # the thread budget counts only this test's runs
            PYTHONPATH=str(ROOT) + os.pathsep + env.get("PYTHONPATH", ""),
        )
        env.update(extra)
        return env

    def cmd(self, *args: str) -> list[str]:
        return [sys.executable, "-m", "twinkit", *args]

    def run(self, *args: str, env: dict | None = None, timeout: float = 120, outputs: bool = True) -> CliResult:
        argv = list(args)
        if outputs and argv and argv[0] not in ("plugins", "verify"):
            argv.append(f"engine.outputs_dir={self.out}")
        p = subprocess.run(self.cmd(*argv), capture_output=True, text=True, env=env or self.env(),
                           cwd=self.tmp, timeout=timeout)
        return CliResult(p.returncode, p.stdout, p.stderr)

    def popen(self, *args: str, env: dict | None = None) -> subprocess.Popen:
        # Ctrl-C must reach the run as it would from a terminal, even when the test suite itself was
        # started in the background (a shell starts background jobs with SIGINT ignored, and children
        # inherit that)
        return subprocess.Popen(self.cmd(*args, f"engine.outputs_dir={self.out}"), env=env or self.env(),
                                cwd=self.tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True, preexec_fn=_default_sigint)

    def counts(self) -> dict[str, int]:
        if not self.counter.exists():
            return {}
        out: dict[str, int] = {}
        for line in self.counter.read_text().split():
            out[line] = out.get(line, 0) + 1
        return out

    def reset_counts(self) -> None:
        self.counter.unlink(missing_ok=True)

    @staticmethod
    def status_of(res: CliResult, folder: str) -> str:
        for line in res.text.splitlines():
            if f"] {folder} " in line:
                return line.split()[2]
        raise AssertionError(f"no line for {folder} in:\n{res.text}")


@pytest.fixture
def project(tmp_path) -> Project:
    return Project(tmp_path)
