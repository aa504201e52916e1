"""What a mixed agent (``--actions mixed``: options and one-slot waypoint actions, docs/ddqn.md
"Options and waypoint actions in one network") chooses, on the first validation layouts at 5 / 20 /
25 / 40 kHz: its mean PSNR, the share of the slots of a mission flown under waypoint actions, its
decisions per episode and its three most frequent waypoint actions (eq. 6.2: j * 5 + i flies to the
j-th device at SPEEDS[i], 0 = hover; 15 = home).

    python examples/mixed_choices.py runs/lever/mixed --episodes 200
"""

import argparse

import jax
import numpy as np

from baselines.report import BANDWIDTHS
from semuav_jax.actions import HOME_CODE, NUM_WAYPOINT_ACTIONS
from semuav_jax.agents.agent import Agent
from semuav_jax.agents.policy import greedy_policy, initial_state
from semuav_jax.engine import numbered, observe, slot
from semuav_jax.env import reset_state
from semuav_jax.keys import VALIDATION_SEED, episode_keys
from semuav_jax.metrics import episode_metrics

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("run", help="a finished train.py run folder of a mixed agent")
ap.add_argument("--seed", type=int, default=0, help="the run's seed index (default: %(default)s)")
ap.add_argument("--episodes", type=int, default=200, help="first validation layouts (default: %(default)s)")
args = ap.parse_args()
agent = Agent.from_run(args.run, args.seed)
if agent.config.actions != "mixed":
    raise SystemExit(f"{args.run} chooses {agent.config.actions!r} actions, not mixed ones")
policy = greedy_policy(agent.network, agent.config)


def episode(key, params):
    """One greedy episode: its metrics, the command code sent and whether it ran, per slot, and the decisions."""
    k_reset, k_delay = jax.random.split(key)
    state, _ = numbered(policy, reset_state(k_reset, params), params)

    def body(carry, u):
        state, obs, ps = carry
        new, new_obs, ps, out = slot(policy, u, state, obs, ps, params)
        return (new, new_obs, ps), (out.action, ~state.done, ps[1].decided & ~state.done)

    start = (state, observe(policy, state, params), initial_state(agent.weights, agent.config))
    (last, _, _), (code, live, decided) = jax.lax.scan(body, start, jax.random.uniform(k_delay, (params.K,)))
    return episode_metrics(last, params)["mean_psnr"], code, live, decided


keys = episode_keys(VALIDATION_SEED, args.episodes)
print("| B (kHz) | mean PSNR (dB) | slots under waypoint actions | decisions per episode | most frequent |")
print("|---|---|---|---|---|")
for B in BANDWIDTHS:
    psnr, code, live, decided = map(np.asarray, jax.jit(jax.vmap(episode, (0, None)))(keys, agent.params.replace(B=B)))
    waypoint = (code < HOME_CODE) & live
    counts = np.bincount(HOME_CODE - 1 - code[waypoint], minlength=NUM_WAYPOINT_ACTIONS)
    top = ", ".join(f"{w}: {counts[w] / max(counts.sum(), 1):.0%}" for w in np.argsort(-counts)[:3] if counts[w])
    share, per = waypoint.sum() / live.sum(), decided.sum() / len(psnr)
    print(f"| {B / 1e3:g} | {psnr.mean():.2f} | {share:.1%} | {per:.1f} | {top or 'none'} |")
