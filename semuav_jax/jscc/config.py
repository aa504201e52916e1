"""The DeepJSCC training run's hyper-parameters (docs/deepjscc.md)."""

from __future__ import annotations

import dataclasses

import numpy as np

CHANNELS = ("awgn", "quantized")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Hyper-parameters; ``steps`` fixes the learning-rate schedule (and the run's length)."""

    steps: int = 3600
    batch: int = 64
    lr: float = 2e-3
    snr_db: float = 30.0
    width: int = 32
    seed: int = 0
    monotone_weight: float = 16.0
    monotone_margin: float = 0.0
    monotone_gap: int = 1
    channel: str = "awgn"
    mask_input: bool = False
    synthetic_fraction: float = 0.25
    init_from: str | None = None

    def validate(self) -> None:
        if self.channel not in CHANNELS:
            raise ValueError(f"channel must be one of {CHANNELS}, got {self.channel!r}")
        for name in ("steps", "batch", "width", "monotone_gap"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be a positive integer, got {getattr(self, name)}")
        if not (np.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"lr must be finite and > 0, got {self.lr}")
        if not np.isfinite(self.snr_db):
            raise ValueError(f"snr_db must be finite, got {self.snr_db}")
        if not (np.isfinite(self.monotone_weight) and self.monotone_weight >= 0):
            raise ValueError(f"monotone_weight must be >= 0, got {self.monotone_weight}")
        if not 0.0 <= self.synthetic_fraction <= 1.0:
            raise ValueError(f"synthetic_fraction must be in [0, 1], got {self.synthetic_fraction}")
        if not np.isfinite(self.monotone_margin):
            raise ValueError(f"monotone_margin must be finite, got {self.monotone_margin}")
