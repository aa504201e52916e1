"""The DDQN agent at the BS (docs/ddqn.md): jitted training, evaluation, the fixed paper layout."""

from semuav_jax.agents.agent import Agent
from semuav_jax.agents.ddqn import DDQNConfig, QNetwork, TrainState, double_q_target, make_train
from semuav_jax.agents.evaluate import evaluate_agent, greedy_policy
from semuav_jax.agents.scenarios import PAPER_DEVICE_IMG, PAPER_DEVICE_POS, scenario_params

__all__ = [
    "Agent",
    "DDQNConfig",
    "PAPER_DEVICE_IMG",
    "PAPER_DEVICE_POS",
    "QNetwork",
    "TrainState",
    "double_q_target",
    "evaluate_agent",
    "greedy_policy",
    "make_train",
    "scenario_params",
]
