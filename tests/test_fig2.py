"""Fig. 2's pipeline (semuav_jax/experiments/fig2.py, eval.py): behaviour measures by hand, properties
of a reduced run, determinism (the same numbers on 1 or 2 devices or processes: test_distributed_results.py)."""

import json
from pathlib import Path

import jax
import numpy as np
import pytest

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.scenarios import scenario_params
from semuav_jax.agents.trainer import make_train
from semuav_jax.experiments import fig2
from semuav_jax.experiments.behaviour import behaviour

ROOT = Path(__file__).resolve().parents[1]
GRID = {"bandwidths": (5e3, 25e3), "velocities": (8.9, 16.0), "layouts": 12, "validation_layouts": 6}


def test_behaviour_by_hand(params):
    # one episode of 4 slots, 2 devices; it ends (done) in slot 3, so slot 4 is not live
    v = np.array([[[3.0, 4.0], [6.0, 8.0], [0.0, 1.0], [9.0, 9.0]]])  # speeds 5, 10, 1, (dead)
    x = np.array([[[True, False], [True, False], [False, False], [True, True]]])
    m = np.zeros((1, 4, 2))
    m[0, -1] = [params.M / 2, 0.0]
    done = np.array([[False, False, True, True]])
    b = behaviour({"v": v, "x": x, "m": m, "done": done}, params)
    assert b["speed_transmitting"][0] == pytest.approx(7.5)  # slots 1-2
    assert b["speed_otherwise"][0] == pytest.approx(1.0)  # slot 3
    assert b["dwell_per_served_s"][0] == pytest.approx(2 * 0.5)  # device 0: two live slots in range
    assert b["symbols_per_served"][0] == pytest.approx(0.5)
    assert b["coverage"][0] == 1 and b["mission_time_s"][0] == pytest.approx(1.5)


@pytest.fixture(scope="module")
def reduced(curves, tmp_path_factory):
    params = scenario_params("random", curves, reward_mode="gain")
    fixed = scenario_params("fixed", curves, reward_mode="gain")
    config = DDQNConfig(num_envs=4, total_steps=4 * 250, learning_starts=64, batch_size=16, buffer_size=500)
    tr = make_train(config, params)
    nets = jax.vmap(tr.init)(jax.random.split(jax.random.key(0), 2)).params  # two untrained seeds
    run = lambda stages=None: fig2.run(
        tr.network, nets, config, params, fixed, GRID, workers=1, log=lambda m: None, stages=stages
    )
    from semuav_jax.runfolder import RunFolder

    folder, logged = RunFolder.claim(tmp_path_factory.mktemp("stages"), "eval.py results"), []
    saved = run(fig2.Stages(folder, {"grid": GRID}, log=lambda m: None))
    resumed = run(fig2.Stages(folder, {"grid": GRID}, log=logged.append))
    folder.release()
    return params, run(), saved, resumed, logged


@pytest.mark.slow
def test_reduced_run_properties(reduced):
    params, r, *_ = reduced
    assert [row["B"] for row in r["panel_a"]] == [5e3, 25e3] and r["seeds"] == 2
    for row in r["panel_a"]:
        assert row["agent_arrived"] == 1.0  # the shield brings even an untrained agent home
        for name in ("greedy 8.9", "tsp 8.9", "greedy v_b*", "tsp v_b*", "dwell-switch", "planner"):
            assert row[name]["arrived"] >= 0.99, name
        assert row["planner"]["mean_psnr"][0] > row["greedy 8.9"]["mean_psnr"][0]
    assert set(r["behaviour"]) == {"5 kHz", "25 kHz"}
    for name, b in r["behaviour"]["25 kHz"].items():
        assert 0 <= b["speed_transmitting"][0] <= params.v_max + 1e-3, name
        assert 0 <= b["symbols_per_served"][0] <= 1 and b["dwell_per_served_s"][0] >= 0
    for p in r["panel_b"].values():
        assert all(0 <= s <= 1 for s in p["symbols_per_covered"]) and len(p["coverage"]) == 2
    assert set(r["paths"]) == {
        "agent",
        "greedy v_b*",
        "tsp v_b*",
        "greedy-dwell",
        "tsp-dwell",
        "dwell-switch",
        "planner",
        "exact planner",
        "plan-switch",
    }
    for p in r["paths"].values():
        np.testing.assert_array_equal(p["q"][0], [0.0, 300.0])
        assert len(p["q"]) == round(p["mission_time"] / 0.5) + 1
    text = fig2.markdown({**r, "paths": None})
    assert "DDQN − dwell-switch" in text and "DDQN − plan-switch" in text and "speed while a device transmits" in text


@pytest.mark.slow
def test_identical_under_fixed_keys_and_after_resuming(reduced):
    """A second run gives the same numbers, and so does one that loads every saved step."""
    _, a, b, c, logged = reduced
    a, b, c = (json.dumps({k: v for k, v in x.items() if k != "paths"}, sort_keys=True) for x in (a, b, c))
    assert a == b == c
    assert len(logged) == fig2.stage_count(GRID)
    assert all(m.endswith("(saved before)") for m in logged[:-1]) and logged[-1] == "paths on the paper layout"


def test_eval_out_untouched_by_a_failed_check_and_foreign_files_refused(tmp_path, capsys):
    """eval.py --out: a folder of ours is left as it was when an option fails its check; one holding a
    file we did not write is refused, untouched (test_runfolder has the rules)."""
    from semuav_jax.runfolder import RunFolder

    ours = tmp_path / "ours"
    f = RunFolder.claim(ours, "eval.py results")
    f.write("fig2.md", b"x")
    f.release()
    before = sorted(p.name for p in ours.iterdir())
    code, _ = _eval_main(capsys, "--out", str(ours), "--agent", str(tmp_path / "none"))  # stops at the missing agent
    assert code == 2 and sorted(p.name for p in ours.iterdir()) == before
    out = tmp_path / "o"
    out.mkdir()
    (out / "mine.txt").write_text("kept")
    code, err = _eval_main(capsys, "--quick", "--out", str(out))
    assert code == 2 and "did not write" in err and sorted(p.name for p in out.iterdir()) == ["mine.txt"]


@pytest.mark.slow
def test_figures(reduced, tmp_path):
    from semuav_jax.experiments import figures

    params, r, *_ = reduced
    figures.fig2a(r, tmp_path / "a.png")
    figures.fig2b(r, tmp_path / "b.png")
    figures.fig2c(r["paths"], scenario_params("fixed").replace(B=25e3), tmp_path / "c.png")
    for f in ("a", "b", "c"):
        assert (tmp_path / f"{f}.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--bandwidths", "nan"], "--bandwidths must be finite and > 0"),
        (["--velocities", "0"], "--velocities must be finite and > 0"),
        (["--layouts", "1"], "--layouts must be >= 2"),
        (["--quick", "--agent", "x"], "drop --agent or --quick"),
        (
            ["--bandwidths", "20000.21", "20000.24"],
            "--bandwidths 20000.21 and 20000.24 would both be named 20.0002 kHz",
        ),
        (
            ["--bandwidths", "5000", "25000.000001"],
            "25000.0 and 25000.000001 would both be named 25 kHz",
        ),  # with the panels' 25 kHz
        (["--total-steps", "0"], "unrecognized arguments: --total-steps 0"),  # training options belong to train.py
        (["--total-steps", "-1"], "unrecognized arguments: --total-steps -1"),
    ],
)
def test_eval_bad_options(tmp_path, args, msg, capsys):
    """One line on stderr, exit code 2 (in-process: an exception would fail the test instead)."""
    from semuav_jax.cli import eval as cli_eval

    try:
        code = cli_eval.main(["--out", str(tmp_path / "o"), *args])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    err = capsys.readouterr().err
    assert code == 2 and msg in err.strip().splitlines()[-1] and "Traceback" not in err  # argparse prints usage first


def test_eval_keeps_close_bandwidths_apart(tmp_path):
    """Bandwidths that differ beyond the first digits of their kHz keep their full values and their own
    names (one agent serves every bandwidth: nothing is trained per bandwidth)."""
    from semuav_jax.cli.eval import parse_args

    a = parse_args(["--out", str(tmp_path / "o"), "--bandwidths", "20000.2", "20000.7"])
    assert a.grid["bandwidths"] == (20000.2, 20000.7)
    assert {fig2.khz(b) for b in a.grid["bandwidths"]} == {"20.0002", "20.0007"}


def _eval_main(capsys, *args):
    from semuav_jax.cli.eval import main

    code = main(list(args))
    return code, capsys.readouterr().err


def test_eval_out_or_agent_that_cannot_be_used_is_one_line(tmp_path, capsys):
    """--out a file, under a file or in a folder that takes no files; --agent a run whose config.json
    has no ddqn block or a key DDQNConfig does not know: exit code 2, one line, nothing evaluated."""
    f = tmp_path / "f"
    f.write_text("x")
    for out, msg in (
        (f, "is a file"),
        (f / "sub", "is a file"),
        (Path("/proc/semuav_results"), "cannot write to --out"),
    ):
        code, err = _eval_main(capsys, "--out", str(out), "--agent", str(tmp_path / "none"))
        assert code == 2 and msg in err and err.count("\n") == 1, err
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.msgpack").write_bytes(b"not read")
    config = {
        "scenario": "random",
        "reward_mode": "gain",
        "bandwidth": 25e3,
        "kappa_c": 10.0,
        "ddqn": {**DDQNConfig().to_dict(), "learning_rate": 1e-3},
    }
    (run / "config.json").write_text(json.dumps(config))
    code, err = _eval_main(capsys, "--out", str(tmp_path / "o"), "--agent", str(run))
    assert code == 2 and "unknown key in its agent config: learning_rate" in err and err.count("\n") == 1, err
    del config["ddqn"]
    (run / "config.json").write_text(json.dumps(config))
    code, err = _eval_main(capsys, "--out", str(tmp_path / "o"), "--agent", str(run))
    assert code == 2 and "is not a train.py run config" in err and err.count("\n") == 1, err
    from semuav_jax.cli.compare import main as compare

    assert compare([str(run)]) == 2 and "is not a train.py run config" in capsys.readouterr().err


def test_eval_ctrl_c_is_one_line_exit_130(tmp_path, capsys, monkeypatch):
    from semuav_jax.cli import eval as cli_eval

    def interrupted(argv):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli_eval, "parse_args", interrupted)
    code, err = _eval_main(capsys, "--out", str(tmp_path / "o"))
    assert code == 130 and "interrupted; the same command continues" in err and err.strip().count("\n") == 0
