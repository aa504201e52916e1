"""The demonstration experts of an option agent (agents/demos.py, docs/ddqn.md "Demonstrations")
flown on the first validation layouts at 5 / 20 / 25 / 40 kHz, beside TSP-dwell at its tuned knobs
(the default run's cached references): the constant option (k by bandwidth, the option margin of
eq. 7.9 at ``--option-margin``, along the tour ``--tour``) through the BS's shield at each of
``--shield-margins``, and with
``--switch`` the switch expert (eq. 7.15 over the constant options, every 32 slots; about 3 min per
bandwidth for 200 layouts).

    python examples/demo_experts.py --shield-margins 2 0 --switch
"""

import argparse
import dataclasses
import time

import jax.numpy as jnp

from baselines.dwell import dwell_metrics, tsp_dwell
from baselines.evaluate import tsp_ranks
from baselines.report import BANDWIDTHS
from semuav_jax.agents.demos import expert_policy, switch_expert
from semuav_jax.agents.options import idle
from semuav_jax.agents.run_config import RunConfig
from semuav_jax.experiments.references import references
from semuav_jax.keys import VALIDATION_SEED, episode_keys
from semuav_jax.lookahead import rollout_switching
from semuav_jax.rollout import rollout

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--episodes", type=int, default=200, help="first validation layouts (default: %(default)s)")
ap.add_argument("--shield-margins", type=float, nargs="+", default=[2.0, 0.0], help="seconds (default: 2 0)")
ap.add_argument("--switch", action="store_true", help="also the switch expert")
ap.add_argument(
    "--option-margin",
    type=float,
    default=RunConfig().agent.option_margin,
    help="s, eq. 7.9 (default: the default run's, %(default)s)",
)
ap.add_argument(
    "--tour",
    choices=("replanned", "shortest"),
    default=RunConfig().agent.tour,
    help="the options' tour, eq. 6.5 (default: the default run's, %(default)s)",
)
args = ap.parse_args()

run = RunConfig.from_preset(
    "default", agent={"demo_expert": "switch", "option_margin": args.option_margin, "tour": args.tour}
)
base = run.env_params()
tuned = references(base, BANDWIDTHS, run.eval_episodes, run.validation_episodes)["tuning"]
keys = episode_keys(VALIDATION_SEED, args.episodes)
rank = jnp.asarray(tsp_ranks(keys, base))
for j, B in enumerate(BANDWIDTHS):
    p = base.replace(B=jnp.float32(B))
    t = time.time()
    v_c, k_star, margin = tuned["tsp-dwell"]["knobs"][j]
    tsp = dwell_metrics(tsp_dwell, keys, p, jnp.float32(v_c), jnp.float32(k_star), jnp.float32(margin), rank)
    line = [f"TSP-dwell (v_c {v_c:g}, k* {k_star:g}, margin {margin:g} s) {float(tsp['mean_psnr'].mean()):.2f} dB"]
    for sm in args.shield_margins:
        cfg = dataclasses.replace(run.agent, shield_margin=sm)
        m = rollout(expert_policy(cfg), keys, p, (jnp.int32(0), idle()), state_axes=None)[0]
        line.append(
            f"constant expert, shield {sm:g} s {float(m['mean_psnr'].mean()):.2f} dB "
            f"(arrived {100 * float(m['arrived'].mean()):.1f} %)"
        )
    if args.switch:
        switch = rollout_switching(switch_expert(run.agent), keys, p)[0]["mean_psnr"]
        line.append(f"switch expert {float(switch.mean()):.2f} dB")
    print(f"{B / 1e3:g} kHz: " + "; ".join(line) + f" ({time.time() - t:.0f} s)", flush=True)
