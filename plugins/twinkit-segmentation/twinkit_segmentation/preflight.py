"""The segmentation steps' preflight checks (twinkit/engine/preflight.py): what fails cheaply, before the first
step runs. Left out of the plugin's code hash: a check never changes a result."""
from __future__ import annotations


def classify_geometry_preflight(site, params, inputs) -> list[str]:
    """The 3D classifier's models that the parameters name (``model``, ``ground_model``) exist."""
    from twinkit_segmentation.geometry.model import model_problem

    out = []
    for name in ("model", "ground_model"):
        value = getattr(params, name)
        problem = model_problem(value) if value else None
        if problem:
            out.append(f"steps.classify_geometry.{name}={value}: {problem}")
    return out
