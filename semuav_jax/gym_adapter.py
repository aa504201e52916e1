"""A Gymnasium ``Env`` around the functional :class:`~semuav_jax.env.SemUAVEnv` (docs/env_api.md).

Importing this module registers it with Gymnasium as ``"SemUAV-v0"``, so
``gymnasium.make("SemUAV-v0", B=5e3)`` works; keyword arguments are ``make_params`` overrides.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any, ClassVar

import gymnasium
import jax
import numpy as np
from jax.typing import ArrayLike

from semuav_jax.actions import ENV_ACTION_MODES
from semuav_jax.env import ENV_ID, EnvState, SemUAVEnv, make
from semuav_jax.metrics import episode_metrics
from semuav_jax.params import EnvParams

# The jitted functions take the parameters as an argument, so every adapter with the same static
# parameters (K, M, N, ...) and action mode shares one compiled program; these instances only
# supply the methods.
_ENVS = {mode: SemUAVEnv(actions=mode) for mode in ENV_ACTION_MODES}


@jax.jit
def _reset(key: jax.Array, params: EnvParams) -> tuple[jax.Array, jax.Array, EnvState]:
    key, k = jax.random.split(key)
    obs, state = _ENVS["table"].reset_env(k, params)
    return key, obs, state


@partial(jax.jit, static_argnames="mode")
def _step(
    key: jax.Array, state: EnvState, action: ArrayLike, params: EnvParams, mode: str = "table"
) -> tuple[jax.Array, jax.Array, EnvState, jax.Array, jax.Array, dict[str, jax.Array]]:
    key, k = jax.random.split(key)
    k_step, _ = jax.random.split(k)  # the key gymnax's ``Environment.step(k, ...)`` steps with
    obs, state, reward, terminated, info = _ENVS[mode].step_env(k_step, state, action, params)
    return key, obs, state, reward, terminated, info


_metrics = jax.jit(episode_metrics)


def describe(value: object) -> str:
    """A one-line name of a bad value for an error message: arrays by dtype and shape."""
    if isinstance(value, np.ndarray) and value.ndim > 0:
        return f"{value.dtype} array of shape {value.shape}"
    text = repr(value)
    return text if len(text) <= 80 and "\n" not in text else f"{type(value).__name__} {text[:60]!r}..."


def check_render_mode(render_mode: str | None, offered: Sequence[str]) -> None:
    """One-line ValueError unless ``render_mode`` is None or one of ``offered``."""
    if render_mode is not None and render_mode not in offered:
        raise ValueError(f"render_mode must be None or one of {offered}, got {render_mode!r}")


def gym_spaces(env: SemUAVEnv, params: EnvParams) -> tuple[gymnasium.spaces.Box, gymnasium.spaces.Discrete]:
    """Gymnasium's observation ``Box`` (float32, eq. 5.1) and ``Discrete`` action space of one env."""
    space = env.observation_space(params)
    low, high = np.asarray(space.low, np.float32), np.asarray(space.high, np.float32)
    return gymnasium.spaces.Box(low, high, space.shape, np.float32), gymnasium.spaces.Discrete(env.num_actions)


class SemUAVGymEnv(gymnasium.Env):
    """One SemUAV environment with Gymnasium's API: NumPy float32 observations (eq. 5.1),
    ``Discrete`` actions (``actions="table"``: eq. 6.1; ``"waypoint"``: eq. 6.2), no auto-reset.

    ``reset(seed=s)`` sets the JAX key ``jax.random.key(s)`` (without a seed, the first reset draws
    one from ``np_random``, later ones continue the key chain); each reset and step splits one
    key off it. With the same key chain and actions an episode equals one run with gymnax's
    ``SemUAVEnv.reset``/``step`` until it ends. ``terminated`` is ``state.done`` (eq. 3.9, t = K
    included, see :class:`SemUAVEnv`); ``truncated`` is always False. ``info`` holds
    ``discount``, ``arrived`` and ``delay``; the final step adds the episode's metrics
    (``metrics.episode_metrics``, eq. 8.1: ``mean_psnr``, ``coverage``, ``mission_time``, ...).
    ``render_mode="rgb_array"``: ``render()`` returns the picture of :func:`semuav_jax.render.rgb_frame`.
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, render_mode: str | None = None, actions: str = "table", **params: Any) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        env, self.env_params = make(ENV_ID, actions=actions, **params)
        self.actions, self.render_mode = actions, render_mode
        self._trail = []  # the UAV's positions since the reset, kept for rendering
        self.observation_space, self.action_space = gym_spaces(env, self.env_params)
        self.env_state = None
        self._key = None

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        if seed is not None and (
            isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32
        ):
            raise ValueError(f"seed must be an integer in [0, 2**32) (JAX keys alias seeds modulo 2**32), got {seed!r}")
        super().reset(seed=seed)
        if seed is not None:
            self._key = jax.random.key(seed)
        elif self._key is None:
            self._key = jax.random.key(int(self.np_random.integers(2**31)))
        self._key, obs, self.env_state = _reset(self._key, self.env_params)
        self._trail = [np.asarray(self.env_state.q)] if self.render_mode else []
        return np.array(obs), {}

    def step(self, action: int | np.integer) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self.env_state is None:
            raise RuntimeError("call reset() before step()")
        if isinstance(action, bool) or not self.action_space.contains(action):
            raise ValueError(f"action must be an integer in [0, {self.action_space.n - 1}], got {describe(action)}")
        self._key, obs, self.env_state, reward, terminated, info = _step(
            self._key, self.env_state, np.int32(action), self.env_params, self.actions
        )
        obs, reward, terminated, info = jax.device_get((obs, reward, terminated, info))
        info = {k: v.item() for k, v in info.items()}
        if terminated:
            info |= {k: v.item() for k, v in jax.device_get(_metrics(self.env_state, self.env_params)).items()}
        if self.render_mode:
            self._trail.append(np.asarray(self.env_state.q))
        return np.array(obs), float(reward), bool(terminated), False, info

    def render(self) -> np.ndarray | None:
        """``rgb_array``: an (H, W, 3) uint8 picture of the episode so far; None without render_mode."""
        if self.render_mode is None or self.env_state is None:
            return None
        from semuav_jax.render import rgb_frame

        return rgb_frame(jax.device_get(self.env_state), self.env_params, np.asarray(self._trail))


if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="semuav_jax.gym_adapter:SemUAVGymEnv",
        vector_entry_point="semuav_jax.gym_vector:SemUAVVectorEnv",
    )
