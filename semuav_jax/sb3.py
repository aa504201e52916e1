"""A Stable-Baselines3 ``VecEnv`` over :class:`~semuav_jax.gym_vector.SemUAVVectorEnv` (docs/env_api.md).

``SemUAVVecEnv(num_envs=n, actions="waypoint", B=25e3)`` goes straight into ``DQN``/``PPO``: all n
episodes step in one jitted call. Needs stable-baselines3 (``pip install "semuav-jax[sb3]"``), which
is not a dependency of semuav-jax.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium.vector import AutoresetMode

from semuav_jax.gym_vector import SemUAVVectorEnv

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as e:  # pragma: no cover - exercised only without SB3
    raise ImportError('semuav_jax.sb3 needs stable-baselines3: pip install "semuav-jax[sb3]"') from e

if TYPE_CHECKING:
    import gymnasium
    from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices


def _row_infos(source: dict, rows: np.ndarray) -> list[dict]:
    """One info dict per row of ``rows`` from Gymnasium's batched infos (a key where its mask is
    set), built from one ``.tolist()`` per key: the per-step Python work is one dict per sub-env."""
    keys = [k for k in source if not k.startswith("_") and k not in ("final_obs", "final_info")]
    if not keys:
        return [{} for _ in rows]
    values = zip(*(source[k][rows].tolist() for k in keys))
    masks = [source[f"_{k}"][rows] for k in keys]
    if all(m.all() for m in masks):  # the usual case: every key set for every row
        return [dict(zip(keys, v)) for v in values]
    masks = zip(*(m.tolist() for m in masks))
    return [{k: x for k, x, on in zip(keys, v, m) if on} for v, m in zip(values, masks)]


class SemUAVVecEnv(VecEnv):
    """n SemUAV environments with SB3's ``VecEnv`` API: ``reset() -> obs``, ``step(actions) -> (obs,
    rewards, dones, infos)``, the ended sub-envs reset in the same step with their last observation
    in ``infos[i]["terminal_observation"]`` and the episode metrics of eq. 8.1 in ``infos[i]``, as
    ``DummyVecEnv`` over n ``SemUAVGymEnv`` gives them. ``seed(s)`` seeds sub-env i with s + i at
    the next reset (SB3's convention); ``dones`` are terminations (t = K included, never
    ``TimeLimit.truncated``, docs/env_api.md). Attributes are shared by all sub-envs: ``get_attr``
    and ``set_attr`` read and write the underlying :class:`SemUAVVectorEnv` (``.venv``).
    """

    def __init__(
        self, num_envs: int = 1, actions: str = "table", render_mode: str | None = None, **params: Any
    ) -> None:
        self.venv = SemUAVVectorEnv(num_envs, actions, render_mode, autoreset_mode=AutoresetMode.SAME_STEP, **params)
        super().__init__(self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._actions = None

    def reset(self) -> np.ndarray:
        seeds = None if self._seeds[0] is None else [int(s) for s in self._seeds]
        obs, _ = self.venv.reset(seed=seeds)
        self._reset_seeds()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, rew, term, _, info = self.venv.step(self._actions)
        infos = [None] * self.num_envs
        for source, rows in ((info, np.flatnonzero(~term)), (info.get("final_info", {}), np.flatnonzero(term))):
            for i, d in zip(rows.tolist(), _row_infos(source, rows)):
                infos[i] = d | {"TimeLimit.truncated": False}
        for i in np.flatnonzero(term):
            infos[i]["terminal_observation"] = info["final_obs"][i]
        return obs, rew.astype(np.float32), term, infos

    def close(self) -> None:
        self.venv.close()

    def _count(self, indices: VecEnvIndices) -> int:
        return len(self._get_indices(indices))

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list:
        return [getattr(self.venv, attr_name)] * self._count(indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        if self._count(indices) != self.num_envs:
            raise ValueError("SemUAVVecEnv's attributes are shared by all sub-envs: set_attr needs indices=None")
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list:
        raise NotImplementedError(f"SemUAVVecEnv steps all sub-envs in one call; call {method_name!r} on .venv")

    def env_is_wrapped(self, wrapper_class: type[gymnasium.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * self._count(indices)

    def get_images(self) -> list[np.ndarray | None]:
        return list(self.venv.render() or [None] * self.num_envs)
