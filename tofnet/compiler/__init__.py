"""The compiler: resource budgets, partitioning into cores and the compiled network backends run.

``compile_network(network, budget=LOIHI2, patch=None)`` cuts every core-placed process
into rectangular patches (fixed or automatic), numbers the cores chip by chip and
accounts for the spikes crossing cores. See docs/compiler.md.
"""

from tofnet.compiler.budget import BUDGETS, LOIHI2, Budget, ChipBudget, CoreBudget, named_budget
from tofnet.compiler.compiled import CompiledNetwork, CoreAssignment, LayerMapping, compile_network
from tofnet.compiler.partition import Traffic, auto_patch

__all__ = ["BUDGETS", "LOIHI2", "Budget", "ChipBudget", "CoreBudget", "named_budget", "CompiledNetwork",
           "CoreAssignment", "LayerMapping", "compile_network", "Traffic", "auto_patch"]
