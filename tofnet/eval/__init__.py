"""Accuracy metrics and figures for depth estimates (``tofnet eval``, ``tofnet plot``).

Plots are imported lazily (``tofnet.eval.plots``) so metrics do not pull in matplotlib.
"""

from tofnet.eval.match import Matches, match_estimates
from tofnet.eval.metrics import DEFAULT_WINDOW_S, ErrorStats, Evaluation, WindowStats, evaluate, evaluate_arrays

__all__ = ["Matches", "match_estimates", "ErrorStats", "WindowStats", "Evaluation", "evaluate",
           "evaluate_arrays", "DEFAULT_WINDOW_S"]
