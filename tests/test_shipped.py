"""The shipped agent (semuav_jax/data/agent) is the output of ``python train.py`` and its recorded
evaluation reproduces here."""

import jax
import numpy as np
import pytest

from semuav_jax.agents.evaluate import evaluate_agent, seed_metrics
from semuav_jax.agents.network import q_network
from semuav_jax.agents.run_config import RunConfig
from semuav_jax.agents.runs import EVAL_FILE, load_run, shipped_folder
from semuav_jax.curves import load_curves
from semuav_jax.keys import TEST_SEED, episode_keys
from semuav_jax.provenance import curves_hash


def test_shipped_agent_is_the_default_command():
    import json

    run, nets = load_run(shipped_folder())
    assert run.command == "python train.py" and run.agent == RunConfig.from_preset("default").agent
    assert run.env == RunConfig.from_preset("default").env and run.env["r_g"] == 0.0
    assert run.curves is None and np.asarray(nets["params"]["Dense_0"]["kernel"]).shape[0] == run.seeds == 3
    ev = json.loads((shipped_folder() / EVAL_FILE).read_text())
    assert ev["curves_sha256"] == curves_hash(load_curves().C) and ev["test_seed"] == TEST_SEED
    assert len(ev["commit"].split("+")[0]) == 40


def test_a_reevaluation_keeps_the_recorded_training_time(tmp_path):
    """``semuav-compare`` on a run folder keeps the ``train_wall_s`` of the eval.json it replaces
    (train.py's), and nothing else of it; a missing or broken file gives nothing."""
    import json

    from semuav_jax.experiments.learned import _training_time

    shipped = _training_time(shipped_folder() / EVAL_FILE)
    assert list(shipped) == ["train_wall_s"] and shipped["train_wall_s"] > 60.0
    f = tmp_path / "eval.json"
    f.write_text(json.dumps({"train_wall_s": 12.5, "rows": [], "commit": "x"}))
    assert _training_time(f) == {"train_wall_s": 12.5}
    assert _training_time(tmp_path / "missing.json") == {}
    for broken in ("{broken", "[1, 2]"):
        f.write_text(broken)
        assert _training_time(f) == {}


@pytest.mark.slow
def test_recorded_evaluation_reproduces():
    """Every seed's mean PSNR at 25 kHz on the recorded test layouts, within its recorded 95 % CI."""
    import json

    run, nets = load_run(shipped_folder())
    config = run.agent
    ev = json.loads((shipped_folder() / EVAL_FILE).read_text())
    row = next(r for r in ev["rows"] if r["B"] == 25e3)
    params = run.env_params().replace(B=25e3)
    network = q_network(params, config)
    keys = episode_keys(TEST_SEED, ev["episodes"])
    m = seed_metrics(network, nets, config, keys, params, (25e3,))
    for s, recorded in enumerate(row["seeds"]):
        assert abs(m["mean_psnr"][s, 0].mean() - recorded["mean_psnr"]) <= recorded["ci95"], s


@pytest.mark.slow
def test_seed_metrics_is_a_loop_over_seeds_and_bandwidths():
    """The program vmapped over seeds and B gives each seed's own evaluation at each B exactly."""
    run, nets = load_run(shipped_folder())
    params, config = run.env_params(), run.agent
    network = q_network(params, config)
    keys = episode_keys(7, 12)
    bandwidths = (5e3, 40e3)
    m = seed_metrics(network, nets, config, keys, params, bandwidths)
    for s in range(run.seeds):
        for j, b in enumerate(bandwidths):
            one = evaluate_agent(network, jax.tree.map(lambda x, s=s: x[s], nets), config, keys, params.replace(B=b))
            for k in ("mean_psnr", "arrived", "shield_share"):
                np.testing.assert_array_equal(one[k], m[k][s, j])


@pytest.mark.slow
def test_validation_table_is_the_seeds_on_validation_layouts(capsys):
    """``learned --validation``: one row per seed, each the mean PSNR of that seed's greedy policy on
    the validation layouts (VALIDATION_SEED), not the test ones."""
    from semuav_jax.cli.compare import main
    from semuav_jax.keys import VALIDATION_SEED

    run, nets = load_run(shipped_folder())
    params, config = run.env_params().replace(B=25e3), run.agent
    keys = episode_keys(VALIDATION_SEED, 4)
    assert main([str(shipped_folder()), "--validation", "--validation-episodes", "4"]) == 0
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith(f"| {shipped_folder()}")]
    assert len(rows) == run.seeds
    network = q_network(params, config)
    for s, row in enumerate(rows):
        w = jax.tree.map(lambda x, s=s: x[s], nets)
        val = evaluate_agent(network, w, config, keys, params)["mean_psnr"].mean()
        test = evaluate_agent(network, w, config, episode_keys(TEST_SEED, 4), params)["mean_psnr"].mean()
        cell = float(row.split("|")[5])  # the 25 kHz column
        assert cell == pytest.approx(val, abs=0.006) and abs(cell - test) > 0.01


@pytest.mark.slow
def test_validation_references_are_the_dwell_rules_at_their_tuned_knobs(capsys):
    """``--validation --references``: TSP-dwell's row is TSP-dwell flown at the knobs tuned on the
    same validation layouts (``baselines.report.tune``)."""
    from baselines.dwell import dwell_metrics, tsp_dwell
    from baselines.evaluate import tsp_ranks
    from baselines.report import tune
    from semuav_jax.cli.compare import main
    from semuav_jax.keys import VALIDATION_SEED

    args = [str(shipped_folder()), "--validation", "--references", "--validation-episodes", "8", "--workers", "1"]
    assert main(args) == 0
    row = next(r for r in capsys.readouterr().out.splitlines() if r.startswith("| tsp-dwell"))
    params = load_run(shipped_folder())[0].env_params().replace(B=25e3)
    keys = episode_keys(VALIDATION_SEED, 8)
    knobs = tune(params, (25e3,), 8, workers=1, switch=False)["tsp-dwell"]["knobs"][0]
    m = dwell_metrics(tsp_dwell, keys, params, *knobs, tsp_ranks(keys, params, workers=1))
    assert float(row.split("|")[5]) == pytest.approx(float(m["mean_psnr"].mean()), abs=0.006)
