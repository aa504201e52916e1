"""The train.py command: run folder rules, outputs, resume, clear errors (exit code 2)."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, train_options

from semuav_jax.agents.config import DDQNConfig

TINY = train_options(eval_episodes=4, validation_episodes=4, workers=1)  # with an evaluation of seconds
NO_EVAL = train_options(eval_episodes=0)


def _train(*args):
    return subprocess.run([sys.executable, str(ROOT / "train.py"), *args], capture_output=True, text=True, cwd=ROOT)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, curves_file):
    out = tmp_path_factory.mktemp("runs") / "r"
    res = _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY)
    assert res.returncode == 0, res.stderr
    return out


@pytest.mark.slow
def test_outputs(run_dir):
    for f in (
        "config.json",
        "metrics.csv",
        "learning_curve.png",
        "checkpoint.msgpack",
        "model.msgpack",
        "eval.json",
        "eval.md",
    ):
        assert (run_dir / f).is_file(), f
    cfg = json.loads((run_dir / "config.json").read_text())
    assert cfg["seeds"] == 2 and cfg["agent"]["lr"] == DDQNConfig().lr and cfg["command"].startswith("python train.py")
    rows = list(csv.DictReader(open(run_dir / "metrics.csv")))
    assert len(rows) == 2 * 4  # 2 seeds x 80 / (4 envs x 5 steps) chunks
    ev = json.loads((run_dir / "eval.json").read_text())
    assert [r["B"] for r in ev["rows"]] == [5e3, 20e3, 25e3, 40e3]  # one agent for every bandwidth
    for row in ev["rows"]:
        assert len(row["seeds"]) == 2 and {"greedy v_b*", "tsp v_b*", "planner"} <= set(row["references"])
        assert "minus greedy v_b*" in row["agent"] and 0.0 <= row["agent"]["shield_share"] <= 1.0
        for s in row["seeds"]:  # paired per layout, so the mean margin is the difference of the means
            ref = row["references"]["greedy 8.9"]["mean_psnr"]
            np.testing.assert_allclose(s["minus greedy 8.9"][0], s["mean_psnr"] - ref, atol=1e-4)
            # the default run learns from demonstrations: the margin over its expert, paired likewise
            mine = row["expert"]["mean_psnr"]
            np.testing.assert_allclose(s["minus its expert"][0], s["mean_psnr"] - mine, atol=1e-4)
        assert row["expert"]["k"] == {5e3: 16.0, 40e3: 32.0}.get(row["B"], 48.0)  # demo_k between demo_edges
    assert len(ev["commit"]) >= 40 and len(ev["curves_sha256"]) == 64


@pytest.mark.slow
def test_options_come_from_the_config_and_the_preset(tmp_path, curves_file):
    """--preset paper sets the paper's agent; a config field given on the command line overrides it."""
    out = tmp_path / "p"
    res = _train(
        "--curves",
        curves_file,
        "--out",
        str(out),
        "--preset",
        "paper",
        "--hidden",
        "32",
        "16",
        "--shield-margin",
        "none",
        *train_options(eval_episodes=0, demo_steps=0),
    )
    assert res.returncode == 0, res.stderr
    cfg = json.loads((out / "config.json").read_text())
    d = cfg["agent"]
    assert (d["actions"], d["lr"], d["n_step"], d["bandwidth_range"]) == ("table", 5e-5, 1, None)
    assert d["hidden"] == [32, 16] and d["shield_margin"] is None and cfg["env"]["reward_mode"] == "paper"


@pytest.mark.slow
def test_same_seed_same_weights(run_dir, curves_file, tmp_path):
    """A second fresh run of the same command writes bit-identical weights (and a different seed does not)."""
    same, other = tmp_path / "same", tmp_path / "other"
    assert _train("--curves", curves_file, "--out", str(same), "--seeds", "2", *NO_EVAL).returncode == 0
    assert (
        _train(
            "--curves",
            curves_file,
            "--out",
            str(other),
            "--seeds",
            "2",
            "--seed",
            "1",
            *NO_EVAL,
        ).returncode
        == 0
    )
    assert (same / "model.msgpack").read_bytes() == (run_dir / "model.msgpack").read_bytes()
    assert (other / "model.msgpack").read_bytes() != (run_dir / "model.msgpack").read_bytes()


@pytest.mark.slow
def test_refuses_existing_folder(run_dir, curves_file):
    res = _train("--curves", curves_file, "--out", str(run_dir), *TINY)
    assert res.returncode == 2
    assert "--resume" in res.stderr and "Traceback" not in res.stderr


@pytest.mark.slow
def test_interrupted_run_resumes_exactly(run_dir, curves_file, tmp_path):
    """Stop after one of two segments, resume: the final weights equal those of the uninterrupted run."""
    out = tmp_path / "r"
    res = _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY, "--max-segments", "1")
    assert res.returncode == 0, res.stderr
    assert "continue with --resume" in res.stdout and not (out / "model.msgpack").exists()
    res = _train("--out", str(out), "--resume")  # the saved run config, its evaluation options too
    assert res.returncode == 0, res.stderr
    assert "resuming" in res.stdout
    assert (out / "model.msgpack").read_bytes() == (run_dir / "model.msgpack").read_bytes()
    assert (out / "metrics.csv").read_bytes() == (run_dir / "metrics.csv").read_bytes()


@pytest.mark.slow
def test_resume_drops_metrics_rows_the_checkpoint_lacks(run_dir, curves_file, tmp_path):
    """metrics.csv is written before the checkpoint; rows of a chunk whose checkpoint a kill
    prevented are dropped on resume, so the resumed run's metrics equal the uninterrupted run's."""
    out = tmp_path / "r"
    assert (
        _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY, "--max-segments", "1").returncode == 0
    )
    with open(out / "metrics.csv", "a") as f:
        f.write("0,3,1,1,1,1,1,1,1,1,1\n")
    (out / "checkpoint.msgpack.abcd1234.tmp").write_bytes(b"half a checkpoint")
    res = _train("--out", str(out), "--resume")  # the saved run config, its evaluation options too
    assert res.returncode == 0, res.stderr
    assert (out / "metrics.csv").read_bytes() == (run_dir / "metrics.csv").read_bytes()
    assert not (out / "checkpoint.msgpack.abcd1234.tmp").exists()


@pytest.mark.slow
def test_resume_refuses_other_options_and_broken_checkpoints(curves_file, tmp_path):
    out = tmp_path / "r"
    assert (
        _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY, "--max-segments", "1").returncode == 0
    )
    res = _train(
        "--out",
        str(out),
        "--resume",
        "--seed",
        "5",
        "--num-envs",
        "4",
        "--bandwidth",
        "5000",
        "--total-steps",
        "160",
        "--curves",
        "synthetic",
    )
    assert res.returncode == 2 and "--seed 5 (saved 0)" in res.stderr and "--num-envs" not in res.stderr
    for clash in (
        "--env B=5000.0 (saved 25000.0)",
        "--total-steps 160 (saved 80)",
        f"--curves synthetic (saved {curves_file})",
    ):
        assert clash in res.stderr, res.stderr
    ckpt = (out / "checkpoint.msgpack").read_bytes()
    (out / "checkpoint.msgpack").write_bytes(ckpt[: len(ckpt) // 2])
    res = _train("--out", str(out), "--resume")
    assert res.returncode == 2 and "unreadable" in res.stderr and "Traceback" not in res.stderr
    cfg = json.loads((out / "config.json").read_text())
    cfg["agent"]["hidden"] = [8]
    (out / "config.json").write_text(json.dumps(cfg))
    (out / "checkpoint.msgpack").write_bytes(ckpt)
    res = _train("--out", str(out), "--resume")
    assert res.returncode == 2 and "was edited after the run wrote it" in res.stderr and "Traceback" not in res.stderr


@pytest.mark.slow
def test_overwrite_deletes_only_run_files(curves_file, tmp_path):
    """--overwrite: a folder without our marker is refused even when it holds only run-file names
    (they may be the user's); in a run folder of ours only the files its manifest lists go."""
    out = tmp_path / "r"
    out.mkdir()
    (out / "config.json").write_text("{}")
    (out / "notes.txt").write_text("mine")
    res = _train("--curves", curves_file, "--out", str(out), *TINY, "--overwrite")
    assert res.returncode == 2 and "did not write" in res.stderr and "notes.txt" in res.stderr
    assert (out / "notes.txt").read_text() == "mine" and (out / "config.json").read_text() == "{}"
    (out / "notes.txt").unlink()
    res = _train("--curves", curves_file, "--out", str(out), *TINY, "--overwrite")
    assert res.returncode == 2 and (out / "config.json").read_text() == "{}"
    (out / "config.json").unlink()
    assert _train("--curves", curves_file, "--out", str(out), *NO_EVAL).returncode == 0
    (out / "notes.txt").write_text("mine")
    res = _train("--curves", curves_file, "--out", str(out), *NO_EVAL, "--overwrite")
    assert res.returncode == 0, res.stderr
    assert (out / "model.msgpack").is_file() and (out / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--seeds", "0"], "--seeds"),
        (["--total-steps", "3"], "less than one chunk"),
        (["--scenario", "moon"], "invalid choice"),
        (["--bandwidth", "-5"], "B must be > 0, got -5.0"),
        (["--curves", "/nonexistent.npz"], "not found"),
        (["--lr", "nan"], "--lr must be finite and > 0"),
        (["--lr", "inf"], "--lr must be finite and > 0"),
        (["--total-steps", "0"], "--total-steps must be a positive integer"),
        (["--total-steps", "-1"], "--total-steps must be a positive integer"),
        (["--gamma", "nan"], "--gamma must be in [0, 1]"),
        (["--hidden", "0"], "--hidden must be"),
        (["--max-grad-norm", "nan"], "--max-grad-norm must be finite"),
        (["--shield-margin", "inf"], "--shield-margin must be finite"),
        (["--bandwidth-range", "nan", "5e3"], "--bandwidth-range must be"),
    ],
)
def test_bad_options(tmp_path, curves_file, args, msg):
    res = _train("--curves", curves_file, "--out", str(tmp_path / "x"), *args)
    assert res.returncode == 2
    assert msg in res.stderr and "Traceback" not in res.stderr


def test_out_that_is_a_file(tmp_path, curves_file):
    f = tmp_path / "f"
    f.write_text("x")
    for out in (f, f / "sub"):
        res = _train("--curves", curves_file, "--out", str(out), *TINY)
        assert res.returncode == 2 and "is a file" in res.stderr and "Traceback" not in res.stderr
    # a folder nothing can be created in (/proc refuses files even to root)
    res = _train("--curves", curves_file, "--out", "/proc/semuav_run", *TINY)
    assert (
        res.returncode == 2 and "cannot write to --out /proc/semuav_run" in res.stderr and "Traceback" not in res.stderr
    )


def _resume_error(capsys, out) -> str:
    from semuav_jax.cli.train import main

    assert main(["--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error: " in err and "Traceback" not in err
    return err


def test_resume_of_a_broken_run_config_is_one_line(tmp_path, capsys):
    """config.json without its agent or env block, with a key DDQNConfig does not know, or not JSON:
    --resume stops with one line (exit code 2) naming the file, before anything is loaded."""
    from semuav_jax.cli.train import parse_args, run_config

    good = run_config(parse_args(["--out", str(tmp_path / "x"), "--curves", "synthetic"])).to_dict()
    out = tmp_path / "r"
    out.mkdir()
    (out / "checkpoint.msgpack").write_bytes(b"not read")
    for broken, msg in (
        ({k: v for k, v in good.items() if k != "agent"}, "no 'agent'"),
        ({k: v for k, v in good.items() if k != "env"}, "no 'env'"),
        ({**good, "agent": {**good["agent"], "learning_rate": 1e-3}}, "unknown key in its agent config: learning_rate"),
        ([1, 2], "not a train.py run config"),
    ):
        (out / "config.json").write_text(json.dumps(broken))
        err = _resume_error(capsys, out)
        assert msg in err and str(out / "config.json") in err, err
    (out / "config.json").write_text("{trunc")
    assert "not a train.py run config" in _resume_error(capsys, out)
