"""The DDQN agent at the BS (docs/ddqn.md): jitted training, evaluation, the fixed paper layout."""

from semuav_jax.agents.agent import Agent
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.evaluate import evaluate_agent
from semuav_jax.agents.network import QNetwork
from semuav_jax.agents.policy import greedy_policy
from semuav_jax.agents.run_config import RunConfig
from semuav_jax.agents.scenarios import PAPER_DEVICE_IMG, PAPER_DEVICE_POS, scenario_params
from semuav_jax.agents.trainer import TrainState, double_q_target, make_train

__all__ = [
    "Agent",
    "DDQNConfig",
    "PAPER_DEVICE_IMG",
    "PAPER_DEVICE_POS",
    "QNetwork",
    "RunConfig",
    "TrainState",
    "double_q_target",
    "evaluate_agent",
    "greedy_policy",
    "make_train",
    "scenario_params",
]
