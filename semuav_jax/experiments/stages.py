"""Saved steps of a long computation (eval.py's Fig. 2, docs/RESULTS.md): each step is written to
``<sub>/<name>.msgpack`` of a claimed output folder (``semuav_jax.runfolder``) together with the key
of everything that made it (grid, layouts, agent weights, curves, commit), so an interrupted run
continues at the first step not done, and a step saved under another key, or one that does not
parse, is recomputed (and said so), never reused."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import numpy as np
from flax import serialization

from semuav_jax.distributed import is_main
from semuav_jax.sharding import agree

if TYPE_CHECKING:
    from semuav_jax.runfolder import RunFolder

FORMAT = "semuav-jax stage 1"


class Stages:
    """``stages(name, compute, save, load, describe)``: the step's result, loaded when saved under
    this ``key`` (JSON-able) in ``folder`` (a :class:`semuav_jax.runfolder.RunFolder`; None: nothing
    saved), else computed and saved. ``log`` gets one line per step, ``note`` the others."""

    def __init__(
        self,
        folder: RunFolder | None,
        key: dict,
        log: Callable[[str], None] = print,
        sub: str = "stages",
        note: Callable[[str], None] | None = None,
    ) -> None:
        self.folder, self.log, self.sub, self.note = folder, log, sub, note or log
        self.key = json.dumps(key, sort_keys=True, default=str)

    def _saved(self, name: str, rel: str, load: Callable[[Any], Any]) -> tuple[Any] | None:
        """The step saved at ``rel`` when it is ours, parses and has this key; else None (said why)."""
        if self.folder is None or rel not in self.folder.files or not (self.folder.path / rel).is_file():
            return None
        try:
            blob = serialization.msgpack_restore((self.folder.path / rel).read_bytes())
            ok = isinstance(blob, dict) and blob.get("format") == FORMAT
            if ok and blob.get("key") == self.key:
                return (load(blob["value"]),)
            why = "was saved for another grid, agent, curves or commit" if ok else "is not a saved step"
        except Exception as e:  # noqa: BLE001 - a truncated or crafted file raises anything: recompute it
            why = f"does not parse ({type(e).__name__})"
        self.note(f"{name}: the saved {rel} {why}: recomputing it")
        return None

    def __call__(
        self,
        name: str,
        compute: Callable[[], Any],
        save: Callable[[Any], Any] = lambda x: x,
        load: Callable[[Any], Any] = lambda x: x,
        describe: Callable[[Any], str] = lambda out: "",
    ) -> Any:
        rel = f"{self.sub}/{name.split(' (')[0].replace(' ', '_')}.msgpack"
        saved = self._saved(name, rel, load)
        if agree(saved is not None):  # a step every process can read (a shared folder)
            self.log(f"{name}{describe(saved[0])} (saved before)")
            return saved[0]
        out = compute()
        if self.folder is not None and is_main():
            blob = {"format": FORMAT, "key": self.key, "value": packable(save(out))}
            self.folder.write(rel, serialization.msgpack_serialize(blob))
        self.log(name + describe(out))
        return out


def packable(x: Any) -> Any:
    """x with tuples as lists and NumPy scalars as Python numbers (what msgpack takes); a restored
    step compares equal in JSON."""
    if isinstance(x, dict):
        return {k: packable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [packable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return np.asarray(x) if isinstance(x, jax.Array) else x
