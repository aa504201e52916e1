"""The episode axis is sharded over forced host CPU devices, with the same results as on one device."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax, numpy as np
    sys.path.insert(0, "tests")
    from conftest import synthetic_curves
    from semuav_jax.params import make_params
    from semuav_jax.rollout import random_policy, random_policy_state, rollout
    from semuav_jax.sharding import shard_episodes

    p = make_params(synthetic_curves(), K=60)
    keys = jax.random.split(jax.random.key(0), 7)
    draws = jax.vmap(random_policy_state, (0, None))(jax.random.split(jax.random.key(1), 7), p)
    plain, _ = rollout(random_policy, keys, p, policy_state=draws)
    skeys, sdraws = shard_episodes((keys, draws))
    sharded, _ = rollout(random_policy, skeys, p, policy_state=sdraws)
    print(json.dumps({
        "devices": jax.device_count(),
        "input_devices": len(skeys.sharding.device_set),
        "output_devices": len(sharded["return"].sharding.device_set),
        "padded": int(skeys.shape[0]),
        "max_diff": max(float(np.max(np.abs(np.asarray(sharded[k][:7], float) - np.asarray(plain[k], float))))
                        for k in plain),
    }))
    """
)


def test_episode_axis_is_sharded_over_host_devices():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", SCRIPT], cwd=root, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["devices"] == 2 and res["input_devices"] == 2 and res["output_devices"] == 2
    assert res["padded"] == 8  # 7 episodes padded to a multiple of 2
    assert res["max_diff"] < 1e-3
