"""A Gymnasium ``VectorEnv`` of n SemUAV environments, stepped by one jitted, vmapped call (docs/env_api.md).

``gymnasium.make_vec("SemUAV-v0", num_envs=n, vectorization_mode="vector_entry_point", ...)``
builds it (``import semuav_jax.gym_adapter`` registers the id); sub-env i is episode for episode
the ``SemUAVGymEnv`` that Gymnasium's ``SyncVectorEnv`` would hold, at a fraction of the cost.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, ClassVar

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space
from jax.typing import ArrayLike

from semuav_jax.env import ENV_ID, EnvState, make
from semuav_jax.gym_adapter import _reset, _step, check_render_mode, describe, gym_spaces
from semuav_jax.metrics import episode_metrics
from semuav_jax.params import EnvParams

SEED_LIMIT = 2**32  # jax.random.key takes 32-bit seeds
SUBSET_MIN = 64  # above this many sub-envs, up to n // 16 resets or metrics are computed on their rows only

_vector_reset = jax.jit(jax.vmap(_reset, (0, None)))


def _replace_rows(mask: jax.Array, fn: Callable[[Any], Any], args: Any, base: Any, size: int) -> Any:
    """``base`` with the rows where ``mask`` is set replaced by the rows of ``fn(args)`` (``fn`` acts
    row by row), computing ``fn`` only when some row needs it and, if at most ``size`` do, only on
    those rows (gathered, then scattered back): a few resets among 4096 sub-envs cost a few."""
    n = mask.shape[0]

    def every(_):
        new = fn(args)
        return jax.tree.map(lambda a, b: jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b), new, base)

    def some(_):
        idx = jnp.nonzero(mask, size=size, fill_value=n)[0]  # n: a padding row, dropped by the scatter
        new = fn(jax.tree.map(lambda a: jnp.take(a, idx, axis=0, mode="clip"), args))
        return jax.tree.map(lambda b, a: b.at[idx].set(a, mode="drop"), base, new)

    count = mask.sum()
    if size >= n:
        return jax.lax.cond(count > 0, every, lambda _: base, None)
    return jax.lax.switch(jnp.minimum(count, 1) + (count > size), [lambda _: base, some, every], None)


def _pack(columns: list) -> tuple[jax.Array, jax.Array]:
    """(n,) columns as one (n, k) float32 matrix (ints are small counts: exact) and one bool matrix,
    so that a step copies two arrays to the host instead of one per info key."""
    floats = [c.astype(jnp.float32) for c in columns if c.dtype != bool]
    return jnp.stack(floats, -1), jnp.stack([c for c in columns if c.dtype == bool], -1)


@partial(jax.jit, static_argnames=("mode", "same_step", "size"), donate_argnames=("keys", "states"))
def _vector_step(
    keys: jax.Array,
    states: EnvState,
    actions: ArrayLike,
    autoreset: ArrayLike,
    params: EnvParams,
    mode: str,
    same_step: bool,
    size: int,
) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, jax.Array, jax.Array | None]:
    """Every sub-env's slot (eq. 3.1-3.10) in one call. Next-step mode: the ``autoreset`` ones reset
    instead of stepping; same-step mode: the ones that end reset right after their step. Resets and
    episode metrics (eq. 8.1) are computed only for the sub-envs that need them (``_replace_rows``).
    Returns the new keys and states (kept on the device) and, for the host, the observations and
    the packed columns reward, terminated, infos, metrics (``_pack``; layout in ``_Columns``)."""
    k_s, obs_s, s_s, rew, term, info = jax.vmap(_step, (0, 0, 0, None, None))(keys, states, actions, params, mode)
    pick = term if same_step else autoreset
    key, obs, state = _replace_rows(
        pick, lambda k: _vector_reset(k, params), k_s if same_step else keys, (k_s, obs_s, s_s), size
    )
    if not same_step:
        rew, term = jnp.where(autoreset, 0.0, rew), term & ~autoreset
    metrics = jax.vmap(episode_metrics, (0, None))
    zeros = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), jax.eval_shape(metrics, s_s, params))
    m = _replace_rows(term, lambda s: metrics(s, params), s_s, zeros, size)
    floats, flags = _pack([rew, term, *info.values(), *m.values()])
    return key, state, obs, floats, flags, obs_s if same_step else None


class _Columns:
    """Where ``_pack`` puts each step info and episode metric, and the batched infos built from them."""

    def __init__(self, params: EnvParams, mode: str) -> None:
        key = jax.random.key(0)
        _, _, state = jax.eval_shape(_reset, key, params)
        info = jax.eval_shape(_step, key, state, jnp.int32(0), params, mode)[-1]
        metrics = jax.eval_shape(episode_metrics, state, params)
        self.keys = []  # (name, is a metric, in the bool matrix, column, dtype)
        metric = {False: [False], True: [False]}  # column 0: the reward / terminated
        for is_metric, d in ((False, info), (True, metrics)):
            for k, v in d.items():
                flag = v.dtype == bool
                self.keys.append((k, is_metric, flag, len(metric[flag]), np.dtype(v.dtype)))
                metric[flag].append(is_metric)
        self.metric = {flag: np.array(m) for flag, m in metric.items()}

    def infos(self, floats: np.ndarray, flags: np.ndarray, live: np.ndarray, ended: np.ndarray) -> dict:
        """Infos as Gymnasium's vector envs batch them: the step's infos for the ``live`` sub-envs
        and the episode metrics (eq. 8.1) for the ``ended`` ones, each key with its mask ``_key``, a
        key only if some sub-env has it, 0 where masked out; "arrived" and "valid", in both, take
        the metric's value where the episode ended."""
        masked = {
            flag: np.where(np.where(self.metric[flag], ended[:, None], live[:, None]), m, np.zeros((), m.dtype))
            for flag, m in ((False, floats), (True, flags))
        }
        out, any_live, any_ended = {}, live.any(), ended.any()
        for k, is_metric, flag, j, dtype in self.keys:
            if not (any_ended if is_metric else any_live):
                continue
            v = masked[flag][:, j].astype(dtype, copy=False)
            if k in out:
                out[k] = np.where(ended, v, out[k])
            else:
                out |= {k: v, f"_{k}": ended if is_metric else live}
        return out


def _seeds(seed: int | Sequence[int], n: int) -> np.ndarray:
    """(n,) uint32 seeds: ``seed + i`` for an int (as ``SyncVectorEnv``), or a list of n ints."""
    s = [seed + i for i in range(n)] if isinstance(seed, (int, np.integer)) else seed
    if (
        not isinstance(s, (list, tuple))
        or len(s) != n
        or not all(isinstance(x, (int, np.integer)) and 0 <= x < SEED_LIMIT for x in s)
    ):
        raise ValueError(f"seed must be an int in [0, 2**32 - num_envs] or a list of num_envs such ints, got {seed!r}")
    return np.asarray(s, np.uint32)


class SemUAVVectorEnv(gymnasium.vector.VectorEnv):
    """n SemUAV environments (``actions="table"``: eq. 6.1; ``"waypoint"``: eq. 6.2) with Gymnasium 1.x's
    ``VectorEnv`` API and next-step autoreset (``AutoresetMode.NEXT_STEP``).

    Each sub-env keeps its own JAX key chain, exactly as ``SemUAVGymEnv``: ``reset(seed=s)`` sets
    sub-env i's key to ``jax.random.key(s + i)`` (or ``seed[i]`` for a list), ``reset()`` without a
    seed continues every chain (the first one draws the seeds from ``np_random``). A sub-env whose
    last step returned ``terminated`` is reset by the next ``step``: its action is ignored, it
    returns the new episode's first observation, reward 0 and ``terminated`` False. ``info``
    holds, as Gymnasium batches infos, ``discount``, ``arrived``, ``delay`` and ``valid`` (with the
    masks ``_discount``, ... False for the sub-envs reset in that step) and, for sub-envs whose
    episode ended, the metrics of eq. 8.1 (``mean_psnr``, ..., masks ``_mean_psnr``, ...).
    ``truncated`` is always False (t = K is a true terminal, docs/env_api.md).
    ``autoreset_mode=AutoresetMode.SAME_STEP`` (what SB3 expects, :mod:`semuav_jax.sb3`) resets a
    sub-env in the step that ends it and moves that step's observation and info to
    ``info["final_obs"]`` / ``info["final_info"]``, as Gymnasium's ``SyncVectorEnv`` does.
    """

    metadata: ClassVar[dict] = {
        "autoreset_mode": AutoresetMode.NEXT_STEP,
        "render_modes": ["rgb_array"],
        "render_fps": 10,
    }

    def __init__(
        self,
        num_envs: int = 1,
        actions: str = "table",
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode = AutoresetMode.NEXT_STEP,
        **params: Any,
    ) -> None:
        if autoreset_mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode must be AutoresetMode.NEXT_STEP or SAME_STEP, got {autoreset_mode!r}")
        self.metadata = self.metadata | {"autoreset_mode": autoreset_mode}
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        check_render_mode(render_mode, self.metadata["render_modes"])
        env, self.env_params = make(ENV_ID, actions=actions, **params)
        self.num_envs, self.actions, self.render_mode = int(num_envs), actions, render_mode
        self.single_observation_space, self.single_action_space = gym_spaces(env, self.env_params)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.state = None  # the batched EnvState, leading axis num_envs (its buffers are reused by step)
        self._keys = None
        self._params = jax.device_put(self.env_params)  # once: Python floats cost a conversion per call
        self._columns = _Columns(self._params, actions)
        self._size = self.num_envs if self.num_envs <= SUBSET_MIN else self.num_envs // 16
        self._autoreset = np.zeros(self.num_envs, bool)
        self._trails = None  # rgb_array only: each sub-env's positions since its reset

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        seeds = None if seed is None else _seeds(seed, self.num_envs)
        super().reset(seed=None if seeds is None else int(seeds[0]))
        if seeds is not None:
            self._keys = jax.vmap(jax.random.key)(seeds)
        elif self._keys is None:
            self._keys = jax.vmap(jax.random.key)(_seeds(int(self.np_random.integers(2**31)), self.num_envs))
        self._keys, obs, self.state = _vector_reset(self._keys, self._params)
        self._autoreset = np.zeros(self.num_envs, bool)
        if self.render_mode is not None:
            self._trails = [[q] for q in np.asarray(self.state.q)]
        return np.asarray(obs), {}

    def step(self, actions: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        actions = self._check_actions(actions)
        reset = self._autoreset
        same_step = self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
        self._keys, self.state, *out = _vector_step(
            self._keys, self.state, actions, reset, self._params, self.actions, same_step, self._size
        )
        obs, floats, flags, final_obs = jax.device_get(out)
        rew, term = floats[:, 0].astype(np.float64), flags[:, 0].copy()
        if same_step:
            infos = self._columns.infos(floats, flags, ~term, np.zeros_like(term))
            if term.any():
                final = np.full(self.num_envs, None, object)
                for i in np.flatnonzero(term):
                    final[i] = final_obs[i]
                infos |= {
                    "final_obs": final,
                    "_final_obs": term,
                    "final_info": self._columns.infos(floats, flags, term, term),
                    "_final_info": term,
                }
        else:
            infos = self._columns.infos(floats, flags, ~reset, term)
            self._autoreset = term
        if self.render_mode is not None:
            self._follow(term if same_step else reset)
        return obs, rew, term, np.zeros(self.num_envs, bool), infos

    def _check_actions(self, actions: npt.ArrayLike) -> np.ndarray:
        try:
            a = np.asarray(actions)
        except ValueError:  # a ragged list
            raise ValueError(
                f"actions must be an integer array of shape ({self.num_envs},), got {describe(actions)}"
            ) from None
        if a.shape != (self.num_envs,) or a.dtype.kind not in "iu":
            raise ValueError(f"actions must be an integer array of shape ({self.num_envs},), got {a.dtype} {a.shape}")
        n = self.single_action_space.n
        if a.size and (a.min() < 0 or a.max() >= n):
            raise ValueError(f"actions must lie in [0, {n - 1}], got values in [{a.min()}, {a.max()}]")
        return a.astype(np.int32)

    def _follow(self, reset: np.ndarray) -> None:
        for i, q in enumerate(np.asarray(self.state.q)):
            if reset[i]:
                self._trails[i] = []
            self._trails[i].append(q)

    def render(self) -> tuple[np.ndarray, ...] | None:
        """``rgb_array``: one (H, W, 3) uint8 frame per sub-env (``semuav_jax.render``); None otherwise."""
        if self.render_mode is None or self.state is None:
            return None
        from semuav_jax.render import rgb_frame

        states = jax.device_get(self.state)
        return tuple(
            rgb_frame(jax.tree.map(lambda x, i=i: x[i], states), self.env_params, np.asarray(self._trails[i]))
            for i in range(self.num_envs)
        )
