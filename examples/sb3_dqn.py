"""Train stable-baselines3's DQN on the vectorized env (waypoint actions) and score it next to ours.

stable-baselines3 and torch are not dependencies of semuav-jax; install them next to it:

    pip install -e ".[sb3]"
    python examples/sb3_dqn.py --timesteps 200000 --envs 16

DQN learns on ``semuav_jax.sb3.SemUAVVecEnv`` (``--envs`` episodes stepped in one jitted call) with
the 16 waypoint actions of eq. 6.2, the action space our DDQN uses. Then every policy flies the
same ``--episodes`` test layouts, drawn by one ``SemUAVVectorEnv`` seeded TEST_SEED + i: DQN greedy,
DQN behind the BS's shield (``VectorShieldWrapper``) and uniformly random waypoint actions step that
env; the shipped DDQN (its own input features, options and shield), greedy-dwell and TSP-dwell (the
references of docs/baselines.md, at the knobs tuned on the validation layouts and recorded in the
shipped agent's eval.json) fly ``rollout`` from the same initial states. Prints mean PSNR (eq. 8.1)
with its 95 % CI, arrival per policy and the wall times; numbers in docs/env_api.md.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
import torch
from stable_baselines3 import DQN

from baselines.dwell import DWELL_POLICIES, init_dwell
from baselines.report import tune
from baselines.tsp import solve_orders
from semuav_jax.agents.agent import Agent
from semuav_jax.agents.gym_shield import VectorShieldWrapper
from semuav_jax.agents.policy import greedy_policy, initial_state
from semuav_jax.agents.runs import shipped_folder
from semuav_jax.experiments.animation import shipped_tuned_speeds
from semuav_jax.gym_vector import SemUAVVectorEnv
from semuav_jax.keys import episode_keys
from semuav_jax.rollout import rollout
from semuav_jax.sb3 import SemUAVVecEnv

TEST_SEED = 1_000_000  # sub-env i of the test env is seeded TEST_SEED + i: layouts never drawn in training


def score(env, act, episodes: int) -> tuple[np.ndarray, np.ndarray]:
    """PSNR and arrival of the first episode of each of ``episodes`` sub-envs under ``act(obs)``."""
    obs, _ = env.reset(seed=TEST_SEED)
    psnr, arrived = np.full(episodes, np.nan), np.zeros(episodes, bool)
    while np.isnan(psnr).any():
        obs, _, term, _, info = env.step(act(obs))
        first = term & np.isnan(psnr)
        if first.any():
            psnr[first], arrived[first] = info["mean_psnr"][first], info["arrived"][first]
    return psnr, arrived


def rollout_scores(test: SemUAVVectorEnv, agent: Agent, knobs: dict, episodes: int) -> dict:
    """PSNR and arrival of the shipped DDQN (its own input, options and shield) and of greedy-dwell
    and TSP-dwell at ``knobs`` ({name: (v_c, k*, margin)}) from the test env's initial states (the
    same layouts; ``rollout`` draws its own delays)."""
    test.reset(seed=TEST_SEED)
    s0, p = jax.device_get(test.state), test.env_params
    keys = episode_keys(TEST_SEED, episodes)
    ddqn = greedy_policy(agent.network, agent.config)
    m = rollout(ddqn, keys, p, initial_state(agent.weights, agent.config), init_state=s0, state_axes=None)[0]
    out = {"our DDQN (shipped: its own input features, actions and shield)": m}
    order = solve_orders(s0.dev_pos, np.asarray(p.q0), np.asarray(p.q_fin))
    rank = np.argsort(order, axis=-1).astype(np.int32)
    for name, policy in DWELL_POLICIES.items():
        ps = jax.vmap(init_dwell, (None, None, None, 0))(*knobs[name], rank)
        out[f"{name} {knobs[name]}"] = rollout(policy, keys, p, ps, init_state=s0)[0]
    return {name: (np.asarray(m["mean_psnr"]), np.asarray(m["arrived"])) for name, m in out.items()}


def dwell_knobs(params, B: float, validation: int) -> dict:
    """The dwell rules' knobs at B: the shipped agent's eval.json, else tuned on ``validation`` layouts."""
    tuned = shipped_tuned_speeds(shipped_folder(), B)
    if tuned is None or any(n not in tuned for n in DWELL_POLICIES):
        print(f"tuning the dwell knobs at {B / 1e3:g} kHz on {validation} validation layouts")
        t = tune(params, (B,), validation, switch=False)
        tuned = {n: tuple(t[n]["knobs"][0]) for n in DWELL_POLICIES}
    return {n: tuple(float(x) for x in tuned[n]) for n in DWELL_POLICIES}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timesteps", type=int, default=200_000, help="environment steps of training (all envs)")
    ap.add_argument("--envs", type=int, default=16, help="episodes stepped together in training")
    ap.add_argument("--episodes", type=int, default=200, help="test layouts")
    ap.add_argument("--B", type=float, default=25e3, help="bandwidth, Hz")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--validation-layouts", type=int, default=200, help="for tuning the dwell knobs when not shipped")
    args = ap.parse_args()
    t_start = time.perf_counter()

    torch.set_num_threads(1)  # a 2 x 64 MLP: one thread is the fastest
    params = {"B": args.B, "reward_mode": "gain", "actions": "waypoint"}
    model = DQN(
        "MlpPolicy",
        SemUAVVecEnv(num_envs=args.envs, **params),
        learning_rate=2.5e-4,
        buffer_size=min(args.timesteps, 200_000),
        learning_starts=5_000,
        train_freq=1,
        gradient_steps=2,
        exploration_fraction=0.3,
        target_update_interval=500,
        gamma=0.99,
        policy_kwargs={"net_arch": [64, 64]},
        seed=args.seed,
    )
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.timesteps)
    train_s = time.perf_counter() - t0

    test = SemUAVVectorEnv(num_envs=args.episodes, **params)
    rng = np.random.default_rng(args.seed)
    dqn = lambda obs: model.predict(obs, deterministic=True)[0]
    rows = {
        f"SB3 DQN, {args.timesteps} steps": score(test, dqn, args.episodes),
        "SB3 DQN behind the shield": score(VectorShieldWrapper(test), dqn, args.episodes),
    }
    knobs = dwell_knobs(test.env_params, args.B, args.validation_layouts)
    rows |= rollout_scores(test, Agent.shipped(), knobs, args.episodes)
    rows["random waypoint actions"] = score(test, lambda obs: rng.integers(0, 16, args.episodes), args.episodes)
    print(
        f"B = {args.B / 1e3:g} kHz, {args.episodes} test layouts; DQN trained on {args.envs} envs "
        f"in {train_s:.0f} s ({args.timesteps / train_s:,.0f} env steps/s); "
        f"wall time {time.perf_counter() - t_start:.0f} s in all"
    )
    print("| policy | mean PSNR (dB) | arrived |\n|---|---|---|")
    for name, (psnr, arr) in rows.items():
        ci = 1.96 * psnr.std(ddof=1) / np.sqrt(len(psnr))
        print(f"| {name} | {psnr.mean():.2f} ± {ci:.2f} | {arr.mean():.0%} |")


if __name__ == "__main__":
    main()
