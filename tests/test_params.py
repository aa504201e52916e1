"""Parameter validation: a ValueError that names the parameter and its allowed range (issue 2)."""

import numpy as np
import pytest
from conftest import synthetic_curves

from semuav_jax.actions import num_actions
from semuav_jax.curves import PSNRCurves, load_curves, save_curves
from semuav_jax.params import make_params, validate_params


def test_defaults_match_model_md(params):
    assert (params.Lx, params.Ly, params.K, params.tau, params.H, params.D_com) == (1000, 600, 250, 0.5, 100, 105)
    assert (params.P_n, params.noise, params.B, params.r_arr, params.a_max, params.v_max) == (
        1e-3,
        1e-9,
        20e3,
        15,
        5,
        25,
    )
    assert params.N == 10 and params.M == 256 and params.levels == 3
    assert num_actions("table", params) == 9 and num_actions("waypoint", params) == 3 * 5 + 1  # eqs. 6.1, 6.2
    np.testing.assert_array_equal(params.q0, [0, 300])
    np.testing.assert_array_equal(params.q_fin, [1000, 300])
    np.testing.assert_array_equal(params.bs_pos, [500, 300])
    assert (params.bs_h, params.P_b, params.B_b, params.L_cmd, params.proc_max, params.beta) == (
        25,
        1,
        100e3,
        64,
        0.1,
        16,
    )
    assert (params.r_g, params.P_miss, params.kappa_d, params.kappa_c, params.eps) == (500, 500, 1, 10, 1e-6)


@pytest.mark.parametrize(
    "override, name",
    [
        ({"B": 0.0}, "B"),
        ({"B": -5e3}, "B"),
        ({"P_n": 0.0}, "P_n"),
        ({"P_b": -1.0}, "P_b"),
        ({"tau": 0.0}, "tau"),
        ({"noise": -1e-9}, "noise"),
        ({"K": 0}, "K"),
        ({"D_com": 100.0}, "D_com"),
        ({"D_com": 50.0}, "D_com"),
        ({"q0": [-1.0, 300.0]}, "q0"),
        ({"q_fin": [1000.0, 601.0]}, "q_fin"),
        ({"reward_mode": "dense"}, "reward_mode"),
        ({"layout": "grid"}, "layout"),
        ({"B": float("nan")}, "B"),
        ({"v_max": float("inf")}, "v_max"),
        ({"B": np.array([5e3, -1.0])}, "B"),
        ({"airspace_margin": -1.0}, "airspace_margin"),
        ({"airspace_margin": float("nan")}, "airspace_margin"),
        ({"N": 0}, "N must be >= 1"),
        ({"eps": 0.0, "reward_mode": "paper"}, "eps must be > 0"),
        ({"P_n": 1e300}, "P_n must be finite"),  # finite in float64, inf in float32
    ],
)
def test_bad_parameter_names_itself(curves, override, name):
    with pytest.raises(ValueError, match=name):
        make_params(curves, **override)


def test_bad_parameter_message_gives_range(curves):
    with pytest.raises(ValueError, match=r"B must be > 0"):
        make_params(curves, B=0.0)
    with pytest.raises(ValueError, match=r"inside the area \[0, Lx\] x \[0, Ly\]"):
        make_params(curves, q0=[0.0, 700.0])


def test_replace_then_validate(params):
    with pytest.raises(ValueError, match="tau"):
        validate_params(params.replace(tau=-0.5))


def test_unknown_parameter(curves):
    with pytest.raises(ValueError, match="unknown parameter"):
        make_params(curves, bandwidth=1.0)


@pytest.mark.parametrize(
    "C, match",
    [
        (np.zeros((4,), np.float32), "shape"),
        (np.full((4, 257), np.nan, np.float32), "non-finite"),
        (np.zeros((4, 257), np.int32), "float"),
    ],
)
def test_bad_curves(C, match):
    with pytest.raises(ValueError, match=match):
        make_params(C)


def test_curves_m_mismatch(curves):
    with pytest.raises(ValueError, match="M"):
        make_params(curves, M=128)


def test_fixed_layout(curves):
    pos = np.array([[100.0, 200.0], [300.0, 400.0]])
    p = make_params(curves, device_pos=pos, device_img=[1, 3], layout="fixed")
    assert p.N == 2
    with pytest.raises(ValueError, match="device_pos"):
        make_params(curves, layout="fixed")
    with pytest.raises(ValueError, match="device_pos"):
        make_params(curves, device_pos=[[2000.0, 0.0]], device_img=[0], layout="fixed")
    with pytest.raises(ValueError, match="device_img"):
        make_params(curves, device_pos=pos, device_img=[0, 99], layout="fixed")


def test_curves_file_roundtrip_and_errors(tmp_path):
    C = synthetic_curves(3, 16)
    path = save_curves(tmp_path / "c.npz", C, {"note": "synthetic"})
    loaded = load_curves(path)
    assert isinstance(loaded, PSNRCurves) and loaded.M == 16 and loaded.meta["note"] == "synthetic"
    np.testing.assert_array_equal(loaded.C, C)
    (tmp_path / "bad.npz").write_bytes(b"not a zip file")
    with pytest.raises(ValueError, match="not a readable curves file"):
        load_curves(tmp_path / "bad.npz")
    np.savez(tmp_path / "wrong.npz", C=C, meta=np.array('{"M": 5}'))
    with pytest.raises(ValueError, match="M = 5"):
        load_curves(tmp_path / "wrong.npz")
    with pytest.raises(FileNotFoundError):
        load_curves(tmp_path / "missing.npz")
