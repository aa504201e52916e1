"""The two demonstration experts of an option agent (agents/demos.py, docs/ddqn.md "Demonstrations")
flown on the first 200 validation layouts at 5 / 20 / 25 / 40 kHz: the constant option (k by
bandwidth) and the switch expert (eq. 7.15 over the constant options, every 32 slots).

    python examples/demo_experts.py
"""

import time

import jax.numpy as jnp

from semuav_jax.agents.demos import expert_policy, switch_expert
from semuav_jax.agents.options import idle
from semuav_jax.agents.run_config import RunConfig
from semuav_jax.keys import VALIDATION_SEED, episode_keys
from semuav_jax.lookahead import rollout_switching
from semuav_jax.rollout import rollout

run = RunConfig.from_preset("default", agent={"actions": "option", "demo_expert": "switch"})
keys = episode_keys(VALIDATION_SEED, 200)
for B in (5e3, 20e3, 25e3, 40e3):
    p = run.env_params().replace(B=jnp.float32(B))
    t = time.time()
    switch = rollout_switching(switch_expert(run.agent), keys, p)[0]["mean_psnr"].mean()
    constant = rollout(expert_policy(run.agent), keys, p, (jnp.int32(0), idle()), state_axes=None)[0]
    print(
        f"{B / 1e3:g} kHz: switch expert {float(switch):.2f} dB, constant expert "
        f"{float(constant['mean_psnr'].mean()):.2f} dB ({time.time() - t:.0f} s)"
    )
