"""The DDQN's hyperparameters (MODEL.md section 6, docs/ddqn.md): one frozen dataclass whose fields
carry their command-line help (``train.py`` derives its options from them).

Network and optimiser follow the paper: MLP 128-128-64 with ReLU, Adam, replay memory of 50 000
transitions. The default learning rate is 2.5e-4 rather than the paper's 5e-5, which learns too
slowly for a 10-minute CPU budget (docs/ddqn.md).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from semuav_jax.actions import ACTION_MODES, OPTION_K, OPTION_MODES

DEMO_EXPERTS = ("constant", "switch")  # agents/demos.py
TOURS = ("replanned", "shortest")  # agents/options.py
SPACINGS = ("linear", "log")  # agents/trainer.py train_bandwidths
SLOTS_PER_OPTION = 16  # slots a random option lasts, about: sizes the warm-up of option agents


def option(default: Any, help: str, **meta: Any) -> Any:
    """A config field with its command-line help and argparse hints (``train.py`` derives its options
    from the fields that have one)."""
    return dataclasses.field(default=default, metadata={"help": help, **meta})


@dataclasses.dataclass(frozen=True)
class DDQNConfig:
    """Hyperparameters (static). ``total_steps`` counts environment steps summed over envs."""

    num_envs: int = option(64, "parallel environments per agent")
    total_steps: int = option(16_000_000, "environment steps per agent, summed over its envs")
    steps_per_chunk: int = option(250, "vmapped env steps per compiled chunk (target sync and metrics per chunk)")
    updates_per_step: int = option(1, "gradient updates after each vmapped env step")
    batch_size: int = option(256, "replay minibatch")
    buffer_size: int = option(50_000, "replay memory, transitions")
    learning_starts: int = option(10_000, "random transitions stored before learning")
    lr: float = option(2.5e-4, "Adam learning rate")
    lr_end: float = option(0.1, "learning rate at the end of training as a share of lr (cosine decay); 1: constant")
    gamma: float = option(0.99, "discount per slot")
    eps_start: float = option(1.0, "initial exploration rate")
    eps_end: float = option(0.02, "final exploration rate")
    eps_decay_frac: float = option(0.5, "share of training over which epsilon decays linearly")
    target_period: int = option(4, "chunks between target-network syncs")
    n_step: int = option(10, "steps summed in each return before bootstrapping")
    reward_scale: float = option(0.01, "multiplies every reward before learning")
    max_grad_norm: float = option(10.0, "global gradient-norm clip")
    hidden: tuple = option((128, 128, 64), "hidden layer widths of the Q-network MLP")
    dueling: bool = option(False, "dueling head: Q = V + A - mean(A) (Wang et al. 2016) instead of one linear layer")
    sorted_devices: bool = option(True, "table actions: sort device blocks nearest first and add tanh offsets")
    shield_margin: float | None = option(
        2.0, "seconds the BS's return-home shield keeps beyond eq. 7.5 (< 0 trusts its over-estimate); none: no shield"
    )
    actions: str = option(
        "waypoint",
        "waypoint (eq. 6.2: device, speed or hover, home), dwell (eq. 6.3: those and stay-until-k over the "
        "nearest device), option (eq. 6.4: serve one of the 4 nearest devices until k symbols, or go home; "
        "one decision per option), mixed (the options and the waypoint actions, each for one slot) or table (the "
        "paper's 9 accelerations)",
    )
    option_inputs: bool = option(
        False,
        "options: add to the input, for every option, the PSNR its device's curve adds, the seconds its stay "
        'takes and the time slack it leaves (docs/ddqn.md, "Input")',
    )
    option_margin: float = option(
        -2.0,
        "options: seconds of time margin of eq. 7.9, the devices an option may serve (that of the tuned dwell rules: "
        "-2; negative: trusts the flight time of eqs. 7.4-7.5 to be that much too long)",
    )
    tour: str = option(
        "replanned",
        "options: the order their tour targets follow (eq. 6.5): replanned (a short path from the UAV through the "
        "devices, re-planned at every decision) or shortest (the BS numbers a layout's devices along the shortest "
        "path q0 -> devices -> q_fin when the episode starts, as TSP-dwell flies it, and follows that order)",
        choices=TOURS,
    )
    demo_steps: int = option(
        0,
        "vmapped env steps the expert option (the first along the tour, k by bandwidth: demo_k, demo_edges) flies "
        "before training; its decisions are a demonstration memory kept for the whole run (DQfD); 0: none",
    )
    demo_batch: int = option(64, "rows of each minibatch drawn from the demonstrations (the rest: replay memory)")
    demo_weight: tuple = option(
        (1.0,),
        "weight of the large-margin loss on the demonstration rows of each minibatch: one for every B, or one per "
        "band below, between and above demo_edges (by each row's bandwidth; 0: none in that band)",
    )
    demo_margin: float = option(0.2, "large margin of Q(s, expert's choice) over every other choice (scaled rewards)")
    demo_k: tuple = option((16.0, 48.0, 32.0), "the expert option's k below, between and above demo_edges")
    demo_edges: tuple = option(
        (7.5e3, 35e3), "Hz: the bandwidths where the expert option's k (and a per-band demo_weight) changes"
    )
    demo_expert: str = option(
        "constant",
        "constant (the option of demo_k and demo_edges at every decision) or switch (every demo_every slots the BS "
        "simulates each constant option, first along the tour or nearest at every k, to the end of the mission and "
        "follows the best: dwell-switch in option space, docs/model.md eq. 7.15)",
        choices=DEMO_EXPERTS,
    )
    demo_every: int = option(32, "slots between two decisions of the switch expert")
    demo_from: float = option(
        0.0, "Hz: the demonstration memory keeps only the decisions of envs at this bandwidth or above (0: every env)"
    )
    bandwidth_range: tuple | None = option(
        (4e3, 45e3),
        "(lo, hi) Hz: the envs train at bandwidths spaced over the range by bandwidth_spacing "
        "(one agent for every B); none: the scenario's B",
    )
    bandwidth_spacing: str = option(
        "linear",
        "how the envs' bandwidths are spaced over bandwidth_range: linear (evenly) or log (geometric: "
        "more envs at low B)",
        choices=SPACINGS,
    )

    def __post_init__(self) -> None:
        for name in ("hidden", "bandwidth_range", "demo_k", "demo_edges"):  # lists (JSON, command line): tuples
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        w = self.demo_weight  # a number (runs before per-band weights) is one weight for every B
        object.__setattr__(self, "demo_weight", tuple(w) if isinstance(w, (list, tuple)) else (w,))
        ints = (
            "num_envs",
            "total_steps",
            "steps_per_chunk",
            "updates_per_step",
            "batch_size",
            "buffer_size",
            "target_period",
            "n_step",
        )
        for name in ints:
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be a positive integer, got {getattr(self, name)}")
        for f in dataclasses.fields(self):
            if "choices" in f.metadata and getattr(self, f.name) not in f.metadata["choices"]:
                raise ValueError(f"{f.name} must be one of {f.metadata['choices']}, got {getattr(self, f.name)!r}")
        if self.shortest_tour and not self.uses_options:
            raise ValueError("tour='shortest' orders the targets of options: it needs actions='option' or 'mixed'")
        if isinstance(self.demo_every, bool) or not isinstance(self.demo_every, int) or self.demo_every < 1:
            raise ValueError(f"demo_every must be an integer >= 1 (slots), got {self.demo_every!r}")
        if int(self.demo_steps) < 0:
            raise ValueError(f"demo_steps must be >= 0, got {self.demo_steps}")
        if self.option_inputs and not self.uses_options:
            raise ValueError("option_inputs describe options: they need actions='option' or 'mixed'")
        if self.demo_steps and not self.uses_options:
            raise ValueError("demonstrations (demo_steps > 0) are options: need actions='option' or 'mixed'")
        if self.demo_steps and not 1 <= int(self.demo_batch) < self.batch_size:
            raise ValueError(f"demo_batch must be in [1, batch_size = {self.batch_size}), got {self.demo_batch}")
        if not all(k in OPTION_K for k in self.demo_k) or len(self.demo_k) != len(self.demo_edges) + 1:
            raise ValueError(
                f"demo_k must hold len(demo_edges) + 1 = {len(self.demo_edges) + 1} of the options' k {OPTION_K}, "
                f"got {self.demo_k}"
            )
        if list(self.demo_edges) != sorted(self.demo_edges) or not all(0 < e < float("inf") for e in self.demo_edges):
            raise ValueError(f"demo_edges must be increasing finite bandwidths > 0 (Hz), got {self.demo_edges}")
        if isinstance(self.demo_from, bool) or not 0.0 <= self.demo_from < float("inf"):
            raise ValueError(f"demo_from must be a finite bandwidth >= 0 (Hz), got {self.demo_from!r}")
        top = float("inf") if self.bandwidth_range is None else self.bandwidth_range[1]
        if self.demo_steps and self.demo_from > top:
            raise ValueError(f"demo_from ({self.demo_from} Hz) is above every training bandwidth: no demonstrations")
        if self.learning_starts < self.batch_size:
            raise ValueError(f"learning_starts ({self.learning_starts}) must be >= batch_size ({self.batch_size})")
        if self.learning_starts > self.buffer_size:
            raise ValueError(f"learning_starts ({self.learning_starts}) must be <= buffer_size ({self.buffer_size})")
        if self.buffer_size < self.num_envs:
            raise ValueError(f"buffer_size ({self.buffer_size}) must be >= num_envs ({self.num_envs})")
        if not 0.0 <= self.eps_end <= self.eps_start <= 1.0:
            raise ValueError(f"need 0 <= eps_end <= eps_start <= 1, got {self.eps_end}, {self.eps_start}")
        if not 0.0 < self.eps_decay_frac <= 1.0:
            raise ValueError(f"eps_decay_frac must be in (0, 1], got {self.eps_decay_frac}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")
        if self.actions not in ACTION_MODES:
            raise ValueError(f"actions must be one of {ACTION_MODES}, got {self.actions!r}")
        if self.bandwidth_range is not None:
            lo, hi = self.bandwidth_range
            if not 0 < lo <= hi < float("inf"):
                raise ValueError(
                    f"bandwidth_range must be (lo, hi) with 0 < lo <= hi, finite, got {self.bandwidth_range}"
                )
        if not self.hidden or not all(isinstance(h, int) and h >= 1 for h in self.hidden):
            raise ValueError(f"hidden must be one or more positive layer widths, got {self.hidden}")
        if not 0.0 < self.lr_end <= 1.0:
            raise ValueError(f"lr_end must be in (0, 1], got {self.lr_end}")
        if isinstance(self.option_margin, bool) or not abs(self.option_margin) < float("inf"):
            raise ValueError(f"option_margin must be a finite number of seconds, got {self.option_margin!r}")
        for name in ("lr", "reward_scale", "max_grad_norm", "demo_margin"):
            if not 0 < getattr(self, name) < float("inf"):  # NaN fails too
                raise ValueError(f"{name} must be finite and > 0, got {getattr(self, name)}")
        w = self.demo_weight  # per band a weight may be 0 (no large-margin loss in that band), not all of them
        if (
            len(w) not in (1, len(self.demo_edges) + 1)
            or not all(not isinstance(x, bool) and isinstance(x, (int, float)) and 0 <= x < float("inf") for x in w)
            or not max(w) > 0
        ):
            raise ValueError(
                f"demo_weight must be one finite weight > 0, or one finite weight >= 0 per band "
                f"({len(self.demo_edges) + 1}: below, between and above demo_edges; not all 0), got {w}"
            )
        if self.shield_margin is not None and not abs(self.shield_margin) < float("inf"):  # NaN fails too
            raise ValueError(f"shield_margin must be finite seconds (none: no shield), got {self.shield_margin}")
        if self.num_chunks < 1:
            raise ValueError(
                f"total_steps ({self.total_steps}) is less than one chunk "
                f"(num_envs * steps_per_chunk = {self.num_envs * self.steps_per_chunk})"
            )

    @property
    def shortest_tour(self) -> bool:
        """Whether the BS numbers a layout's devices along the shortest path and the options follow it."""
        return self.tour == "shortest"

    @property
    def uses_options(self) -> bool:
        """Whether the agent chooses options (eq. 6.4; "mixed": and waypoint actions): one semi-MDP
        transition per decision."""
        return self.actions in OPTION_MODES

    @property
    def warmup_steps(self) -> int:
        """Vmapped env steps of the random warm-up that fills the memory to about ``learning_starts``
        (options store one transition per decision, about every SLOTS_PER_OPTION slots)."""
        per = SLOTS_PER_OPTION if self.uses_options else 1
        return -(-self.learning_starts * per // self.num_envs)

    @property
    def num_chunks(self) -> int:
        return self.total_steps // (self.num_envs * self.steps_per_chunk)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict, where: str = "the agent config") -> DDQNConfig:
        """The config of a JSON object; ValueError (one line) for an unknown key or a bad value."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: the agent config must be a JSON object, got {type(d).__name__}")
        unknown = sorted(set(d) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            keys = ", ".join(unknown)
            raise ValueError(f"{where}: unknown key{'s' * (len(unknown) > 1)} in its agent config: {keys}")
        try:
            return cls(**d)
        except TypeError as e:
            raise ValueError(f"{where}: bad agent config ({e})") from None
