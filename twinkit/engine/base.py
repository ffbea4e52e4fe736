"""The state every part of :class:`~twinkit.engine.runner.Engine` shares, declared once for the type checker.

:class:`Engine` is built from mix-ins (``locks``, ``keys``, ``edits``, ``store``, ``workspace``, ``fanout``,
``manual``, ``status``, ``recipes``), each one concern; they read the attributes that ``Engine.__init__`` sets and
call one another's methods. :class:`EngineBase` declares those attributes and cross-mix-in methods (annotations
only: it sets nothing and defines nothing at run time), so each mix-in is checked against the same names."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from twinkit.engine.locks import StoreLock
    from twinkit.engine.plan import PlannedStep
    from twinkit.engine.records import StepOutcome
    from twinkit.hashing import HashCache
    from twinkit.plugins import Registry


class EngineBase:
    """Attributes set by ``Engine.__init__`` (see :class:`~twinkit.engine.runner.Engine` for their meaning)."""

    cfg: dict
    registry: Registry
    workspace: Path
    site_root: Path
    rerun: set[str]
    interactive: bool
    threads: int
    max_threads: int | None
    config_root: Path | None
    store: Path  # <site>/.cache/steps
    edits_dir: Path  # <site>/.cache/edits
    hashes: HashCache
    executor_factory: Callable[[], Any] | None
    manual_timeout_s: float | None
    skipped: list[tuple[str, str]]
    fallbacks: list[tuple[str, str]]
    plan: list[PlannedStep]
    code_hashes: dict[str, str]  # plugin qualname -> code hash, read when the plan was made
    outcomes: list[StepOutcome]
    current_step: str | None
    secrets: dict[str, str]  # set by the command line after construction; absent otherwise
    _fixed_threads: int | None
    _lock: Any
    _store_lock: StoreLock | None
    _fanout_retry: bool

    if TYPE_CHECKING:  # methods one mix-in calls on another (defined in the module named)
        def _ctx_kwargs(self, ps: PlannedStep) -> dict: ...  # runner

        def _share_threads(self) -> None: ...  # runner

        def _input_values(self, ps: PlannedStep) -> tuple[dict[str, Any], dict[str, Any]]: ...  # keys

        def _descriptor(self, ps: PlannedStep, input_hashes: dict[str, Any]) -> dict: ...  # keys

        def _keyed(self, descriptor: dict) -> tuple[str, dict, str, list[str]]: ...  # keys

        def _why(self, old: dict | None, new: dict) -> str: ...  # keys

        def _check_workspace(self, folder: Path, rec: dict) -> tuple[str, list[str]]: ...  # edits

        def _keep_edits(self, folder: Path, rec: dict | None, why: str,
                        forced: bool = False) -> Path | None: ...  # edits

        def _edit_to_restore(self, ps: PlannedStep, folder: Path, key: str, files: dict,
                             forced: bool) -> tuple[Path, dict] | None: ...  # edits

        def _reapply_edit(self, folder: Path, dest: Path, note: dict) -> list[str]: ...  # edits

        def _pending_edits(self, folder: Path, key: str) -> list[tuple[Path, dict]]: ...  # edits

        def _store_valid(self, key: str) -> dict | None: ...  # store

        def _materialize(self, folder: Path, entries: list[tuple[str, Path]], record: dict) -> None: ...  # workspace

        def _outputs_of(self, folder: Path, ps: PlannedStep, rec: dict,
                        current: bool) -> tuple[dict, dict]: ...  # workspace

        def _workspace_record(self, ps: PlannedStep, key: str, desc: dict, stored: Any, status: str, why: str,
                              in_paths: dict) -> dict: ...  # workspace

        def _redacted(self, obj: Any) -> Any: ...  # workspace
