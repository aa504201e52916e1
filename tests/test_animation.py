"""semuav_jax/experiments/animation.py: episodes side by side as an animated GIF (eval.py --animate)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from PIL import Image

from semuav_jax.agents.scenarios import scenario_params
from semuav_jax.experiments.animation import animate, episode_path
from semuav_jax.rollout import rollout

K = 20


def constant(accel):
    return lambda ps, state, params: (jnp.asarray(accel, jnp.float32), ps)


@pytest.fixture(scope="module")
def fixed(curves):
    return scenario_params("fixed", curves, K=K, B=25e3)


def one_trace(policy, params):
    _, tr = rollout(policy, jax.random.split(jax.random.key(0), 1), params, trace=True)
    return jax.tree.map(lambda x: np.asarray(x)[0], tr)


def test_episode_path_starts_at_q0_and_stops_at_done(fixed):
    tr = one_trace(constant([5.0, 0.0]), fixed)
    tr["done"] = np.arange(K) >= 6  # as if the episode ended in slot 7 (t = 7)
    p = episode_path(tr, fixed)
    assert p["q"].shape == (8, 2) and p["m"].shape == (8, fixed.N) and p["phi"].shape == (7, fixed.N)
    np.testing.assert_array_equal(p["q"][0], np.asarray(fixed.q0))
    np.testing.assert_array_equal(p["q"][1:], tr["q"][:7])
    assert not p["m"][0].any() and not p["x"][0].any()


def test_animate_writes_one_frame_per_stride_and_holds_the_end(fixed, tmp_path):
    traces = {"east": one_trace(constant([5.0, 0.0]), fixed), "north-east": one_trace(constant([5.0, 5.0]), fixed)}
    out = animate(traces, fixed, tmp_path / "a.gif", fps=10, stride=5, panel=(3.0, 2.0), dpi=50, hold_s=0.25)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gif"]  # written atomically, no temporary left
    im = Image.open(out)
    assert im.n_frames == 5 and im.size == (300, 130)  # slots 0, 5, 10, 15 and the end, K; 3 x (2 + 0.6) in at 50 dpi
    frames, durations = [], []
    for i in range(im.n_frames):
        im.seek(i)
        frames.append(np.asarray(im.convert("RGB")))
        durations.append(im.info["duration"])
    assert durations == [100, 100, 100, 100, 250]  # 10 frames a second, the end held 0.25 s
    assert (frames[0] != frames[3]).any()  # the UAVs move


@pytest.mark.parametrize(
    "scenario, traces, msg", [("random", {"a": None}, "layout must be 'fixed'"), ("fixed", {}, "at least one trace")]
)
def test_animate_bad_input(curves, tmp_path, scenario, traces, msg):
    with pytest.raises(ValueError, match=msg):
        animate(traces, scenario_params(scenario, curves, K=K), tmp_path / "a.gif")


def test_eval_animate_needs_a_gif_name(tmp_path, capsys):
    from semuav_jax.cli import eval as cli_eval

    assert cli_eval.main(["--animate", str(tmp_path / "a.mp4")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("--animate must name a .gif file, got '" + str(tmp_path / "a.mp4") + "'") and "\n" not in err
