"""A training run, whole (docs/ddqn.md, "Run config"): the env (scenario, curves and ``make_params``
overrides), the agent (``DDQNConfig``) and the run's options. ``train.py`` builds it from its
options (derived from these fields), writes it as the run folder's config.json, and every reader
(``eval.py``, the experiments, ``Agent``) rebuilds the run's ``EnvParams`` from it with
:meth:`RunConfig.env_params`: a run trained with any override is evaluated with it.

Presets are the one place for the defaults of a run that differ from ``EnvParams``'s: each has an
env part and an agent part.
"""

from __future__ import annotations

import dataclasses
import json
import math
from typing import TYPE_CHECKING, Any

from semuav_jax.agents.config import DDQNConfig, option
from semuav_jax.agents.scenarios import SCENARIOS, scenario_params
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    import numpy as np

    from semuav_jax.curves import PSNRCurves

FORMAT = "semuav-jax run 2"
SEED_RANGE = 2**32  # jax.random.PRNGKey aliases seeds modulo 2**32

# one agent for every B: the 'gain' reward (docs/ddqn.md) and no arrival bonus (the shield guarantees arrival,
# and a discounted bonus only pays for arriving early)
ONE_AGENT_ENV = {"reward_mode": "gain", "B": 25e3, "r_g": 0.0}
PRESETS = {
    # options (eq. 6.4) along the shortest path with the option inputs, the constant expert's demonstrations with
    # the large-margin loss weighted 0.25 below 7.5 kHz, 4 up to 35 kHz and 16 above, the shield at -3 s and the
    # option margin of eq. 7.9 at -4 s (docs/ddqn.md, "Options" and "The large-margin loss weighted by band")
    "default": {
        "env": ONE_AGENT_ENV,
        "agent": {"actions": "option", "gamma": 0.995, "demo_steps": 2500, "demo_weight": (0.25, 4.0, 16.0),
                  "shield_margin": -3.0, "option_margin": -4.0, "tour": "shortest", "option_inputs": True},
    },
    # the default env with the waypoint agent (eq. 6.2): one decision per slot
    "waypoint": {"env": ONE_AGENT_ENV, "agent": {}},
    # the paper's configuration (MODEL.md section 6, PAPER_CLAIMS.md): paper reward with the shield, lr 5e-5,
    # MLP 128-128-64, the 9 accelerations, the raw observation, 1-step targets, trained at one bandwidth
    "paper": {
        "env": {"reward_mode": "paper", "B": 25e3, "r_g": 500.0},
        "agent": {"actions": "table", "sorted_devices": False, "lr": 5e-5, "hidden": (128, 128, 64), "n_step": 1,
                  "gamma": 0.999, "bandwidth_range": None, "dueling": False, "lr_end": 1.0},
    },
}  # fmt: skip

# make_params keys a run may not override: the layout comes from the scenario, the curves from ``curves``
NOT_ENV = ("C", "device_pos", "device_img", "layout")


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """What a training run is; :meth:`to_dict` is config.json. Run options carry their CLI help."""

    agent: DDQNConfig = dataclasses.field(default_factory=lambda: DDQNConfig(**PRESETS["default"]["agent"]))
    env: dict = dataclasses.field(default_factory=lambda: dict(PRESETS["default"]["env"]))
    scenario: str = option("random", "fixed: the paper layout; random: a new layout per episode", choices=SCENARIOS)
    curves: str | None = option(None, "PSNR curves .npz, or 'synthetic' (none: the shipped DeepJSCC curves)", type=str)
    seed: int = option(0, "base random seed")
    seeds: int = option(3, "independent agents trained in one program")
    segments: int = option(50, "host-level segments (progress + checkpoint each)")
    eval_episodes: int = option(1000, "test layouts of the comparison with the references after training (0: none)")
    validation_episodes: int = option(500, "validation layouts that tune the references' knobs")
    workers: int = option(2, "processes for OR-Tools and the planner in the evaluation")
    preset: str = "default"
    command: str = ""

    def __post_init__(self) -> None:
        bad = lambda name, want: ValueError(f"{name} must be {want}, got {getattr(self, name)!r}")
        integer = lambda v: isinstance(v, int) and not isinstance(v, bool)
        for name in ("seeds", "segments", "validation_episodes", "workers"):
            if not integer(getattr(self, name)) or getattr(self, name) < 1:
                raise bad(name, "an integer >= 1")
        if not integer(self.seed) or not 0 <= self.seed < SEED_RANGE:
            raise bad("seed", "an integer in [0, 2**32) (random keys alias seeds modulo 2**32)")
        if not integer(self.eval_episodes) or self.eval_episodes < 0 or self.eval_episodes == 1:
            raise bad("eval_episodes", "0 (no comparison) or an integer >= 2 (its intervals need two)")
        if self.scenario not in SCENARIOS:
            raise bad("scenario", f"one of {SCENARIOS}")
        if self.preset not in PRESETS:
            raise bad("preset", f"one of {tuple(PRESETS)}")
        if self.curves is not None and not isinstance(self.curves, str):
            raise bad("curves", "a file name, 'synthetic' or null")
        if not isinstance(self.agent, DDQNConfig):
            raise bad("agent", "a DDQNConfig")
        if not isinstance(self.env, dict):
            raise bad("env", "a mapping of make_params overrides")
        unknown = sorted(set(self.env) - (set(EnvParams.__dataclass_fields__) - set(NOT_ENV)))
        if unknown:
            raise ValueError(f"env: unknown or not overridable parameter(s) {unknown}")
        for k, v in self.env.items():
            if isinstance(v, bool) or (isinstance(v, float) and not math.isfinite(v)):
                raise ValueError(f"env: {k} must be a finite number, got {v!r}")

    @classmethod
    def from_preset(
        cls, preset: str = "default", env: dict | None = None, agent: dict | None = None, **run: Any
    ) -> RunConfig:
        """The preset's env and agent parts with ``env`` / ``agent`` overrides and the run options ``run``."""
        if preset not in PRESETS:
            raise ValueError(f"preset must be one of {tuple(PRESETS)}, got {preset!r}")
        p = PRESETS[preset]
        config = DDQNConfig(**{**p["agent"], **(agent or {})})
        return cls(agent=config, env={**p["env"], **(env or {})}, preset=preset, **run)

    def env_params(self, scenario: str | None = None, curves: PSNRCurves | np.ndarray | None = None) -> EnvParams:
        """The run's ``EnvParams`` (of another ``scenario`` or ``curves`` when given): ValueError (one
        line) for an override ``make_params`` refuses or a curves file that does not load."""
        from semuav_jax.curves import load_curves, synthetic_curves

        if curves is None and self.curves is not None:
            curves = synthetic_curves() if self.curves == "synthetic" else load_curves(self.curves)
        try:
            return scenario_params(scenario or self.scenario, curves, **self.env)
        except (TypeError, KeyError) as e:
            raise ValueError(f"env: {e}") from None

    def replace(self, **changes: Any) -> RunConfig:
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return json.loads(json.dumps({"format": FORMAT, **d, "agent": self.agent.to_dict()}))

    @classmethod
    def from_dict(cls, d: Any, where: str = "the run config") -> RunConfig:
        """The config of a config.json object (format 2, or format 1 of earlier run folders); ValueError
        (one line, naming ``where``) for anything that is not one or holds a value the options refuse."""
        if isinstance(d, dict) and "format" not in d and isinstance(d.get("ddqn"), dict):
            d = _from_format_1(d)
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"{where} is not a train.py run config (no 'format': {FORMAT!r})")
        missing = [repr(k) for k in ("agent", "env") if k not in d]
        if missing:
            raise ValueError(f"{where} is not a train.py run config (no {', '.join(missing)})")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - names - {"format"})
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {unknown}")
        body = {k: v for k, v in d.items() if k in names}
        try:
            body["agent"] = DDQNConfig.from_dict(body.get("agent", {}), where)
            return cls(**body)
        except (TypeError, ValueError) as e:
            text = str(e)
            raise ValueError(text if text.startswith(str(where)) else f"{where}: {text}") from None


def _from_format_1(d: dict) -> dict:
    """A format-1 config.json (scenario fields at the top, the agent under 'ddqn') in format 2."""
    env = {"reward_mode": d.get("reward_mode"), "B": d.get("bandwidth"), "kappa_c": d.get("kappa_c")}
    env["r_g"] = d.get("r_g", 500.0)  # format 1 without r_g trained with EnvParams' default
    run = {k: d[k] for k in ("preset", "scenario", "curves", "seed", "seeds", "segments", "command") if k in d}
    return {"format": FORMAT, **run, "env": env, "agent": d["ddqn"]}
