"""A plain NumPy transcription of MODEL.md sections 2-4, one env, float64, written from the spec
independently of the JAX code: the tests' oracle and the benchmark's baseline (benchmarks/env_throughput.py)."""

import math

import numpy as np


def a2g_path_loss_db(r, dh, p):
    theta = math.degrees(math.atan2(dh, r))
    p_los = 1.0 / (1.0 + p["los_a"] * math.exp(-p["los_b"] * (theta - p["los_a"])))
    d = math.hypot(r, dh)
    return 20 * math.log10(4 * math.pi * p["f_c"] * d / p["c"]) + p_los * p["eta_los"] + (1 - p_los) * p["eta_nlos"]


def a2g_rate(r, dh, power, bandwidth, p):
    snr = power / (p["noise"] * 10 ** (a2g_path_loss_db(r, dh, p) / 10))
    return bandwidth * math.log2(1 + snr)


def speed_cap(v, w, R, h, iters=2000):
    """The point of {|x| <= R} and {|x - v|_inf <= h} nearest to v + w, by Dykstra's alternating
    projections (independent of the closed form in kinematics.py); v + w when |v + w| <= R."""
    c = v + w
    if np.linalg.norm(c) <= R:
        return c
    x, p, q = c.copy(), np.zeros(2), np.zeros(2)
    for _ in range(iters):
        y = x + p
        y_new = y * min(1.0, R / np.linalg.norm(y))
        p, z = y - y_new, y_new + q
        x = np.clip(z, v - h, v + h)
        q = z - x
    return x


class NumpyEnv:
    """State: q, v, a_prev, t, m, phi, dev_pos, dev_img, done, arrived."""

    def __init__(self, p, C, dev_pos, dev_img):
        self.p, self.C = p, np.asarray(C, np.float64)
        self.dev_pos, self.dev_img = np.asarray(dev_pos, np.float64), np.asarray(dev_img)
        self.q = np.array(p["q0"], np.float64)
        self.v = np.zeros(2)
        self.a_prev = np.zeros(2)
        self.t = 0
        self.m = np.zeros(len(dev_pos))
        self.phi = self.C[self.dev_img, 0].copy()
        self.done = self.arrived = False

    def step(self, accel, u):
        """One slot with command ``accel`` and processing-delay draw u in [0, 1); returns the reward."""
        p = self.p
        if self.done:
            return 0.0
        a = np.clip(accel, -p["a_max"], p["a_max"])
        rb = a2g_rate(np.linalg.norm(self.q - p["bs_pos"]), p["H"] - p["bs_h"], p["P_b"], p["B_b"], p)
        delay = min(p["tau"], u * p["proc_max"] + p["L_cmd"] / rb)
        a_eff = (delay * self.a_prev + (p["tau"] - delay) * a) / p["tau"]
        v = speed_cap(self.v, a_eff * p["tau"], p["v_max"], p["a_max"] * p["tau"])
        q = self.q + v * p["tau"]  # no wall: the UAV may leave the area
        m = p.get("airspace_margin", math.inf)
        outside = bool(np.any(q < -m) or q[0] > p["Lx"] + m or q[1] > p["Ly"] + m)
        dist_prev = np.linalg.norm(self.q - p["q_fin"])
        r = np.linalg.norm(self.dev_pos - q, axis=1)
        x = (np.hypot(r, p["H"]) <= p["D_com"]) & (self.m < p["M"])
        bw = p["B"] / max(x.sum(), 1)
        phi_prev = self.phi
        for n in np.flatnonzero(x):
            self.m[n] = min(p["M"], self.m[n] + a2g_rate(r[n], p["H"], p["P_n"], bw, p) * p["tau"] / p["beta"])
        self.phi = self.C[self.dev_img, np.floor(self.m).astype(int)]
        self.q, self.v, self.a_prev, self.t = q, v, a, self.t + 1
        self.arrived = np.linalg.norm(q - p["q_fin"]) <= p["r_arr"]
        self.done = self.arrived or self.t >= p["K"] or outside
        if p["reward_mode"] == "paper":
            r_c = (x * self.phi).sum() / (x.sum() + p["eps"])
        else:
            r_c = p["kappa_c"] * (self.phi - phi_prev).sum()
        r_d = p["kappa_d"] * (dist_prev - np.linalg.norm(q - p["q_fin"])) / (p["v_max"] * p["tau"])
        r_g = p["r_g"] if self.arrived else 0.0
        r_miss = -p["P_miss"] if (self.done and not self.arrived) else 0.0
        self.delay, self.x = delay, x
        return r_c + r_d + r_g + r_miss


def params_dict(params):
    """The EnvParams fields as plain Python floats / NumPy arrays."""
    out = {}
    for k in params.__dataclass_fields__:
        v = getattr(params, k)
        out[k] = v if isinstance(v, (str, int)) else np.asarray(v, np.float64)
    for k, v in out.items():
        if isinstance(v, np.ndarray) and v.ndim == 0:
            out[k] = float(v)
    return out
