"""The train.py command: run folder rules, outputs, resume, clear errors (exit code 2)."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from semuav_jax.agents.ddqn import DDQNConfig
from semuav_jax.curves import save_curves

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--num-envs", "4", "--steps-per-chunk", "5", "--total-steps", "80", "--learning-starts", "32",
        "--batch-size", "8", "--segments", "2", "--eval-episodes", "4", "--validation-episodes", "4", "--workers", "1"]


def _train(*args):
    return subprocess.run([sys.executable, str(ROOT / "train.py"), *args], capture_output=True, text=True, cwd=ROOT)


@pytest.fixture(scope="module")
def curves_file(tmp_path_factory, curves):
    return str(save_curves(tmp_path_factory.mktemp("c") / "curves.npz", curves, {"source": "synthetic"}))


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, curves_file):
    out = tmp_path_factory.mktemp("runs") / "r"
    res = _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY)
    assert res.returncode == 0, res.stderr
    return out


def test_outputs(run_dir):
    for f in ("config.json", "metrics.csv", "learning_curve.png", "checkpoint.msgpack", "model.msgpack", "eval.json",
              "eval.md"):
        assert (run_dir / f).is_file(), f
    cfg = json.loads((run_dir / "config.json").read_text())
    assert cfg["seeds"] == 2 and cfg["ddqn"]["lr"] == DDQNConfig().lr and cfg["command"].startswith("python train.py")
    rows = list(csv.DictReader(open(run_dir / "metrics.csv")))
    assert len(rows) == 2 * 4  # 2 seeds x 80 / (4 envs x 5 steps) chunks
    ev = json.loads((run_dir / "eval.json").read_text())
    assert [r["B"] for r in ev["rows"]] == [5e3, 20e3, 25e3, 40e3]  # one agent for every bandwidth
    for row in ev["rows"]:
        assert len(row["seeds"]) == 2 and {"greedy v_b*", "tsp v_b*", "planner"} <= set(row["references"])
        assert "minus greedy v_b*" in row["agent"] and 0.0 <= row["agent"]["shield_share"] <= 1.0
    assert len(ev["commit"]) >= 40 and len(ev["curves_sha256"]) == 64


def test_options_come_from_the_config_and_the_preset(tmp_path, curves_file):
    """--preset paper sets the paper's agent; a config field given on the command line overrides it."""
    out = tmp_path / "p"
    res = _train("--curves", curves_file, "--out", str(out), "--preset", "paper", "--hidden", "32", "16",
                 "--shield-margin", "none", *TINY[:-6], "--eval-episodes", "0")
    assert res.returncode == 0, res.stderr
    cfg = json.loads((out / "config.json").read_text())
    d = cfg["ddqn"]
    assert (d["actions"], d["lr"], d["n_step"], d["bandwidth_range"]) == ("table", 5e-5, 1, None)
    assert d["hidden"] == [32, 16] and d["shield_margin"] is None and cfg["reward_mode"] == "paper"


def test_same_seed_same_weights(run_dir, curves_file, tmp_path):
    """A second fresh run of the same command writes bit-identical weights (and a different seed does not)."""
    same, other = tmp_path / "same", tmp_path / "other"
    assert _train("--curves", curves_file, "--out", str(same), "--seeds", "2", *TINY[:-6], "--eval-episodes", "0").returncode == 0
    assert _train("--curves", curves_file, "--out", str(other), "--seeds", "2", "--seed", "1", *TINY[:-6],
                  "--eval-episodes", "0").returncode == 0
    assert (same / "model.msgpack").read_bytes() == (run_dir / "model.msgpack").read_bytes()
    assert (other / "model.msgpack").read_bytes() != (run_dir / "model.msgpack").read_bytes()


def test_refuses_existing_folder(run_dir, curves_file):
    res = _train("--curves", curves_file, "--out", str(run_dir), *TINY)
    assert res.returncode == 2
    assert "--resume" in res.stderr and "Traceback" not in res.stderr


def test_interrupted_run_resumes_exactly(run_dir, curves_file, tmp_path):
    """Stop after one of two segments, resume: the final weights equal those of the uninterrupted run."""
    out = tmp_path / "r"
    res = _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY, "--max-segments", "1")
    assert res.returncode == 0, res.stderr
    assert "continue with --resume" in res.stdout and not (out / "model.msgpack").exists()
    res = _train("--out", str(out), "--resume", "--eval-episodes", "0")
    assert res.returncode == 0, res.stderr
    assert "resuming" in res.stdout
    assert (out / "model.msgpack").read_bytes() == (run_dir / "model.msgpack").read_bytes()
    assert len(list(csv.DictReader(open(out / "metrics.csv")))) == 2 * 4


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--seeds", "0"], "--seeds"),
        (["--total-steps", "3"], "less than one chunk"),
        (["--scenario", "moon"], "invalid choice"),
        (["--bandwidth", "-5"], "B must be > 0"),
        (["--curves", "/nonexistent.npz"], "not found"),
    ],
)
def test_bad_options(tmp_path, curves_file, args, msg):
    res = _train("--curves", curves_file, "--out", str(tmp_path / "x"), *args)
    assert res.returncode == 2
    assert msg in res.stderr and "Traceback" not in res.stderr
