"""Train stable-baselines3's DQN on the vectorized env (waypoint actions) and score it next to ours.

stable-baselines3 and torch are not dependencies of semuav-jax; install them next to it:

    pip install -e ".[sb3]"
    python examples/sb3_dqn.py --timesteps 200000 --envs 16

DQN learns on ``semuav_jax.sb3.SemUAVVecEnv`` (``--envs`` episodes stepped in one jitted call) with
the 16 waypoint actions of eq. 6.2, the action space our DDQN uses. Then every policy flies the
same ``--episodes`` test layouts in one ``SemUAVVectorEnv``: DQN greedy, DQN behind the BS's shield
(``VectorShieldWrapper``), the shipped DDQN (its own input features and shield) and uniformly
random waypoint actions. Prints mean PSNR (eq. 8.1) and arrival per policy; numbers in docs/env_api.md.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
import torch
from stable_baselines3 import DQN

from semuav_jax.agents.agent import Agent
from semuav_jax.agents.gym_shield import VectorShieldWrapper
from semuav_jax.gym_vector import SemUAVVectorEnv
from semuav_jax.sb3 import SemUAVVecEnv

TEST_SEED = 1_000_000  # sub-env i of the test env is seeded TEST_SEED + i: layouts never drawn in training


def score(env, act, episodes: int) -> tuple[float, float]:
    """Mean PSNR and arrival rate of the first episode of each of ``episodes`` sub-envs under ``act(obs)``."""
    obs, _ = env.reset(seed=TEST_SEED)
    psnr, arrived = np.full(episodes, np.nan), np.zeros(episodes, bool)
    while np.isnan(psnr).any():
        obs, _, term, _, info = env.step(act(obs))
        first = term & np.isnan(psnr)
        if first.any():
            psnr[first], arrived[first] = info["mean_psnr"][first], info["arrived"][first]
    return float(psnr.mean()), float(arrived.mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timesteps", type=int, default=200_000, help="environment steps of training (all envs)")
    ap.add_argument("--envs", type=int, default=16, help="episodes stepped together in training")
    ap.add_argument("--episodes", type=int, default=200, help="test layouts")
    ap.add_argument("--B", type=float, default=25e3, help="bandwidth, Hz")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

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
    agent = Agent.shipped()
    agent_act = jax.jit(jax.vmap(lambda s, p: agent.act(s, p)[0], (0, None)))
    rng = np.random.default_rng(args.seed)
    dqn = lambda obs: model.predict(obs, deterministic=True)[0]
    rows = {
        f"SB3 DQN, {args.timesteps} steps": score(test, dqn, args.episodes),
        "SB3 DQN behind the shield": score(VectorShieldWrapper(test), dqn, args.episodes),
        "our DDQN (shipped, shield)": score(
            test, lambda obs: np.asarray(agent_act(test.state, test.env_params)), args.episodes
        ),
        "random waypoint actions": score(test, lambda obs: rng.integers(0, 16, args.episodes), args.episodes),
    }
    print(
        f"B = {args.B / 1e3:g} kHz, {args.episodes} test layouts; DQN trained on {args.envs} envs "
        f"in {train_s:.0f} s ({args.timesteps / train_s:,.0f} env steps/s)"
    )
    print("| policy | mean PSNR (dB) | arrived |\n|---|---|---|")
    for name, (psnr, arr) in rows.items():
        print(f"| {name} | {psnr:.2f} | {arr:.0%} |")


if __name__ == "__main__":
    main()
