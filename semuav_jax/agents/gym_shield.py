"""The BS's shield (docs/ddqn.md, "Shield"; :mod:`semuav_jax.agents.shield`) as Gymnasium wrappers, so
an outside learner on ``SemUAVGymEnv`` / ``SemUAVVectorEnv`` can be scored with and without it.

Each step the wrapper replaces the learner's action by the one the BS sends (table actions:
``shield``; waypoint actions: ``waypoint_shield``) and reports ``info["shielded"]``, True where
the two differ.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Any

import gymnasium
import jax
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from semuav_jax.agents.shield import shield, waypoint_shield

if TYPE_CHECKING:
    from semuav_jax.env import EnvState
    from semuav_jax.params import EnvParams


@partial(jax.jit, static_argnames="mode")
def _sent(action: ArrayLike, state: EnvState, params: EnvParams, margin: float, mode: str) -> jax.Array:
    return (shield if mode == "table" else waypoint_shield)(action, state, params, margin)


_sent_batch = jax.jit(jax.vmap(_sent, (0, 0, None, None, None)), static_argnums=4)


def _check_margin(margin: float) -> float:
    if not (isinstance(margin, (int, float)) and 0 <= margin < float("inf")):
        raise ValueError(f"margin must be a finite number of seconds >= 0, got {margin!r}")
    return float(margin)


class ShieldWrapper(gymnasium.Wrapper):
    """``SemUAVGymEnv`` behind the shield with ``margin`` seconds of slack (the agent's default: 2 s)."""

    def __init__(self, env: gymnasium.Env, margin: float = 2.0) -> None:
        super().__init__(env)
        self.margin = _check_margin(margin)

    def step(self, action: int | np.integer) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        base = self.env.unwrapped
        if base.env_state is None or not self.action_space.contains(action):
            return self.env.step(action)  # the env raises its own error
        sent = int(_sent(np.int32(action), base.env_state, base.env_params, self.margin, base.actions))
        obs, rew, term, trunc, info = self.env.step(sent)
        return obs, rew, term, trunc, info | {"shielded": sent != int(action)}


class VectorShieldWrapper(gymnasium.vector.VectorWrapper):
    """``SemUAVVectorEnv`` behind the shield: every sub-env's action filtered in one jitted call."""

    def __init__(self, env: gymnasium.vector.VectorEnv, margin: float = 2.0) -> None:
        super().__init__(env)
        self.margin = _check_margin(margin)

    def step(self, actions: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        base = self.env.unwrapped
        if base.state is None:
            return self.env.step(actions)  # the env raises its own error
        chosen = base._check_actions(actions)
        sent = np.asarray(_sent_batch(chosen, base.state, base.env_params, self.margin, base.actions))
        obs, rew, term, trunc, info = self.env.step(sent)
        return obs, rew, term, trunc, info | {"shielded": sent != chosen}
