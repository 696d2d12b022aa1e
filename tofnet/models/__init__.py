"""Process models: how each process runs on each backend family (Lava's ``ProcessModel``).

Declarations (``tofnet.processes``) say what a process is; a model here says how it runs
on the ``reference`` (step by step), ``float`` or ``fixed`` (event-driven) backends. Pick
rule and extension points: ``tofnet.models.registry`` and docs/extending.md.
"""

from tofnet.models.base import FAMILIES, Model, ModelContext, StepModel, concat, records
from tofnet.models.registry import families_of, model, model_for, register_model

__all__ = ["FAMILIES", "Model", "ModelContext", "StepModel", "concat", "records", "families_of", "model",
           "model_for", "register_model"]
