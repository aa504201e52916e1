"""semuav-jax: a JAX simulator of a UAV collecting semantically coded images from IoT devices.

``make("SemUAV-v0", **params)`` returns ``(env, env_params)`` like ``gymnax.make``; the
Gymnasium adapter is ``semuav_jax.gym_adapter.SemUAVGymEnv`` (docs/env_api.md).
"""

from semuav_jax.env import SemUAVEnv, make
from semuav_jax.provenance import version

__version__ = version()

__all__ = ["SemUAVEnv", "make", "__version__"]
