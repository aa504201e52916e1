"""Train stable-baselines3's DQN on the Gymnasium adapter and report its mean PSNR (eq. 8.1).

stable-baselines3 and torch are not dependencies of semuav-jax; install them next to it:

    pip install torch --index-url https://download.pytorch.org/whl/cpu
    pip install -e . stable-baselines3
    python examples/sb3_dqn.py --timesteps 50000

The agent sees the observation of eq. 5.1 and picks one of the 9 accelerations of the paper's
table (eq. 6.1) every slot; no shield, no waypoint actions (those are ``semuav_jax.agents``). It
is evaluated greedily on ``--episodes`` random layouts it did not train on, next to a uniformly
random action on the same layouts. Measured numbers are in docs/env_api.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from stable_baselines3 import DQN

from semuav_jax.gym_adapter import SemUAVGymEnv


def evaluate(act, env: SemUAVGymEnv, episodes: int, seed: int) -> tuple[float, float]:
    """Mean PSNR and arrival rate over ``episodes`` episodes, episode i reset with ``seed + i``."""
    psnr, arrived = [], []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        terminated = truncated = False
        while not (terminated or truncated):
            obs, _, terminated, truncated, info = env.step(act(obs))
        psnr.append(info["mean_psnr"])
        arrived.append(info["arrived"])
    return float(np.mean(psnr)), float(np.mean(arrived))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timesteps", type=int, default=50_000, help="environment steps of training (slots)")
    ap.add_argument("--episodes", type=int, default=20, help="evaluation episodes")
    ap.add_argument("--B", type=float, default=20e3, help="bandwidth, Hz")
    ap.add_argument("--reward-mode", default="gain", choices=("gain", "paper"), help="eq. 4.2 or eq. 4.1")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    torch.set_num_threads(1)  # a 2 x 64 MLP: one thread is the fastest
    params = {"B": args.B, "reward_mode": args.reward_mode}
    model = DQN(
        "MlpPolicy",
        SemUAVGymEnv(**params),
        learning_rate=1e-4,
        buffer_size=args.timesteps,
        learning_starts=1_000,
        exploration_fraction=0.3,
        target_update_interval=1_000,
        policy_kwargs={"net_arch": [64, 64]},
        seed=args.seed,  # also seeds the training env's first reset
    )
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.timesteps)
    train_s = time.perf_counter() - t0

    eval_env = SemUAVGymEnv(**params)
    eval_seed = 1_000_000 + args.seed  # layouts not drawn in training
    psnr, arrived = evaluate(lambda o: int(model.predict(o, deterministic=True)[0]), eval_env, args.episodes, eval_seed)
    rng = np.random.default_rng(args.seed)
    n = eval_env.action_space.n
    psnr_rnd, arrived_rnd = evaluate(lambda o: int(rng.integers(n)), eval_env, args.episodes, eval_seed)
    print(f"DQN, {args.timesteps} steps ({train_s:.0f} s of training): mean PSNR {psnr:.2f} dB, "
          f"arrived {arrived:.0%} over {args.episodes} episodes (B = {args.B:g} Hz, reward {args.reward_mode})")
    print(f"random actions on the same layouts: mean PSNR {psnr_rnd:.2f} dB, arrived {arrived_rnd:.0%}")


if __name__ == "__main__":
    main()
