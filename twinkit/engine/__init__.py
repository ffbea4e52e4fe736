"""The step engine: plan a recipe, decide per step whether to run, reuse or keep an edit, and run it.

Layout of a site's outputs (``outputs/<site>/``)::

    01_site/ 02_read_cloud/ ...     one numbered folder per step: the files people open and edit,
                                    plus step.json (what made them, with hashes)
    runs/<run id>/manifest.json     provenance of each run (and run.log)
    .cache/steps/<key>/             results stored by cache key, shared by all runs and multirun jobs
    .cache/hashes.sqlite            stat -> sha256 cache, so unchanged files are never re-read
    .cache/edits/                   hand edits set aside when their step had to re-run

A step's cache key hashes its plugin (kind, name, version, code), its resolved
parameters, the configuration of the components it uses, and the content hashes
of its inputs. Outputs are written in a temporary folder and moved into the store
only when the step returned and every declared output exists; the numbered
folder is then swapped in atomically.

Where each part lives (``twinkit/engine/``):

- ``plan.py``: a recipe's steps -> ordered :class:`PlannedStep` list: plugin, params, wired inputs
- ``params.py``: a plugin's parameters from its dataclass defaults and the config / recipe layers
- ``runner.py``: :class:`Engine`: the loop over the plan and the decision run / reuse / cached per step
- ``base.py``: :class:`EngineBase`: the attributes and methods the Engine's mix-ins share, declared for the type
  checker (every mix-in below inherits it)
- ``keys.py``: a step's cache key: its descriptor (plugin, params, components, input hashes) and why it changed
- ``store.py``: the content store ``.cache/steps/<key>``: atomic compute into it, validity of an entry
- ``records.py``: ``step.json`` records and the :class:`StepOutcome` of a step
- ``workspace.py``: the numbered folders: swapping stored results in atomically, their records and outputs
- ``edits.py``: hand-edit detection in a numbered folder, and setting edits aside
- ``locks.py``: one run per workspace (lock file), writability, leftovers of killed runs
- ``fanout.py``: ``foreach`` steps: one keyed store entry per item, run through an executor
- ``manual.py``: manual steps: instructions, waiting for the files a person provides
- ``status.py``: the dry run (``twinkit status``): what a run would do, writing nothing
- ``memory.py``: a step's peak memory, and handing freed memory back between items
- ``single_step.py``: one plugin run through the same atomic write path, outside any recipe (tests)
- ``garbage.py``: ``twinkit gc``: unreferenced store entries, stale remembered hashes
"""
from twinkit.engine.garbage import collect_garbage, prune_hash_cache
from twinkit.engine.locks import unwritable
from twinkit.engine.plan import GIVEN_KEY, given_params
from twinkit.engine.runner import Engine
from twinkit.engine.single_step import execute_plugin

__all__ = ["Engine", "GIVEN_KEY", "collect_garbage", "execute_plugin", "given_params", "prune_hash_cache",
           "unwritable"]
