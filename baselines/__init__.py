"""Greedy, TSP and straight-flight baselines of MODEL.md section 7 in the functional env."""

from baselines.evaluate import baseline_metrics, evaluate, layouts, run, sweep, tsp_ranks
from baselines.policies import DEFAULT_V_B, POLICIES, BaselineState, greedy, init_state, straight, tsp

__all__ = [
    "DEFAULT_V_B",
    "POLICIES",
    "BaselineState",
    "baseline_metrics",
    "evaluate",
    "greedy",
    "init_state",
    "layouts",
    "run",
    "straight",
    "sweep",
    "tsp",
    "tsp_ranks",
]
