"""The DDQN agent at the BS (docs/ddqn.md): jitted training, evaluation, the fixed paper layout."""

from semuav_jax.agents.ddqn import DDQNConfig, QNetwork, TrainState, agent_features, double_q_target, make_train
from semuav_jax.agents.evaluate import baseline_results, compare, evaluate_agent, greedy_policy
from semuav_jax.agents.scenarios import PAPER_DEVICE_IMG, PAPER_DEVICE_POS, scenario_params

__all__ = [
    "DDQNConfig", "PAPER_DEVICE_IMG", "baseline_results", "PAPER_DEVICE_POS", "QNetwork", "TrainState", "agent_features", "compare",
    "double_q_target", "evaluate_agent", "greedy_policy", "make_train", "scenario_params",
]
