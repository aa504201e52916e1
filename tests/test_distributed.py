"""Several processes of one run (jax.distributed over loopback): sharding primitives, the same
numbers as one process, and bounded failures (docs/scaling.md)."""

import argparse
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from multiprocess import ROOT, end_all, environment, free_port, run, single, start

from semuav_jax import distributed

PRIMITIVES = textwrap.dedent(
    """
    import argparse, json
    from semuav_jax import distributed
    p = argparse.ArgumentParser()
    distributed.add_options(p)
    distributed.initialize(p.parse_args())
    import jax, numpy as np
    from semuav_jax.sharding import agree, gather, map_episodes, shard_episodes, split_hosts
    keys = jax.random.split(jax.random.PRNGKey(3), 7)
    draw = jax.jit(jax.vmap(lambda k: jax.random.uniform(k, (3,))))
    sharded = shard_episodes(keys)
    u = gather(draw(sharded))
    m = map_episodes(lambda k: {"u": draw(k).T, "rows": k.shape[0] + 0 * k[:, 0]}, keys)
    owner = split_hosts(lambda lo, hi: {"i": np.arange(lo, hi), "p": np.full(hi - lo, jax.process_index())}, 7)
    r = {"process": jax.process_index(), "processes": jax.process_count(), "devices": jax.device_count()}
    r["padded"] = int(sharded.shape[0])
    r["local_rows"] = sum(s.data.shape[0] for s in sharded.addressable_shards)
    r["same"] = bool(np.array_equal(u[:7], np.asarray(jax.vmap(lambda k: jax.random.uniform(k, (3,)))(keys))))
    r["padding_repeats_last"] = bool(np.array_equal(u[7:], np.repeat(u[6:7], len(u) - 7, 0)))
    r["blocks_same"], r["block_rows"] = bool(np.array_equal(m["u"], u[:7].T)), m["rows"].tolist()
    r["index"], r["owner"] = owner["i"].tolist(), owner["p"].tolist()
    r["all_true"], r["only_0"] = agree(True), agree(jax.process_index() == 0)
    print(json.dumps(r))
    """
)


@pytest.mark.parametrize("devices", [1, 2])
def test_two_processes_shard_gather_and_split_work(devices):
    codes, texts = run(["-c", PRIMITIVES], 2, limit_s=120, devices=devices)
    assert codes == [0, 0], [t[1][-2000:] for t in texts]
    for i, (out, _) in enumerate(texts):
        r = json.loads(out.strip().splitlines()[-1])
        assert r["process"] == i and r["processes"] == 2 and r["devices"] == 2 * devices
        assert r["padded"] == 8 and r["local_rows"] == 4  # 7 episodes padded to 8, half in each process
        assert r["same"] and r["padding_repeats_last"]  # the keys' draws do not depend on the split
        # fixed-size blocks (episode axis last here): fn sees one block of 7 episodes at a time
        assert r["blocks_same"] and r["block_rows"] == [7] * 7
        assert r["index"] == list(range(7)) and r["owner"] == [0, 0, 0, 0, 1, 1, 1]
        assert r["all_true"] is True and r["only_0"] is False


@pytest.mark.slow
def test_an_episode_s_bits_depend_on_its_block_only(params):
    """map_episodes (one process, one device): the first 64 of 70 episodes (blocks of 64) are the
    bits of a batch of those 64; the episode axis may be first or last."""
    import jax
    import numpy as np

    from baselines import sweep
    from semuav_jax.sharding import BLOCK, map_episodes

    keys = jax.random.split(jax.random.PRNGKey(5), BLOCK + 6)
    m = sweep("greedy", keys, params, v_b=(8.9, 14.0))  # (B, v_b, E): episode axis last
    m_block = sweep("greedy", keys[:BLOCK], params, v_b=(8.9, 14.0))
    assert m["mean_psnr"].shape == (1, 2, BLOCK + 6) and np.ptp(m["mean_psnr"]) > 0
    for k in m_block:
        np.testing.assert_array_equal(m[k][..., :BLOCK], m_block[k], err_msg=k)
    draw = jax.jit(jax.vmap(lambda k: jax.random.uniform(k, (3,))))
    np.testing.assert_array_equal(map_episodes(draw, keys, axis=0), np.asarray(draw(keys)))


def _options(argv):
    p = argparse.ArgumentParser()
    distributed.add_options(p)
    return p.parse_args(argv)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--num-processes", "2"], "need --coordinator"),
        (["--coordinator", "127.0.0.1"], "HOST:PORT"),
        (["--coordinator", "127.0.0.1:99999", "--num-processes", "2", "--process-id", "0"], "HOST:PORT"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "2"], "needs --num-processes and --process-id"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "2"], "0 .. 1"),
        (["--dist-timeout", "0.5"], ">= 2 s"),
    ],
)
def test_bad_distributed_options_are_one_line_errors(argv, message):
    with pytest.raises(distributed.DistributedError, match=message):
        distributed.check_options(_options(argv))
    distributed.check_options(_options([]))  # one process: nothing to check


def test_a_peer_that_never_starts_ends_the_run_within_the_timeout():
    """Process 0 of 2 alone: the start gives up after --dist-timeout with one line, exit code 1."""
    script = textwrap.dedent("""
        import argparse, time
        from semuav_jax import distributed
        p = argparse.ArgumentParser()
        distributed.add_options(p)
        args = p.parse_args()
        print(time.time(), flush=True)
        distributed.initialize(args)
        print("started")
    """)
    p = subprocess.run(
        [
            sys.executable,
            "-c",
            script,
            "--coordinator",
            f"127.0.0.1:{free_port()}",
            "--num-processes",
            "2",
            "--process-id",
            "0",
            "--dist-timeout",
            "5",
        ],
        cwd=ROOT,
        env=environment(),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    waited = time.time() - float(p.stdout.split()[0])
    assert p.returncode == 1, p.stderr[-2000:]
    assert "started" not in p.stdout
    assert (
        p.stderr.strip()
        .splitlines()[-1]
        .endswith(
            "error: could not start the distributed run at 127.0.0.1:"
            + p.args[4].split(":")[1]
            + ": not every process joined within 5 s"
        )
    )
    assert 5 <= waited < 5 + 5  # the timeout, plus the interpreter's exit


GRID = {"episodes": 6, "seeds": [0, 1], "policies": ["greedy", "tsp@15"], "params": {"B": [5e3, 25e3], "K": 60}}


def _sweep_files(out):
    return {p.name: p.read_bytes() for p in sorted((out / "items").glob("*.json"))} | {
        "sweep.csv": (out / "sweep.csv").read_bytes()
    }


@pytest.mark.slow
def test_sweep_items_are_the_same_on_1_or_2_processes_and_devices(tmp_path):
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps(GRID))
    args = ["-m", "semuav_jax.cli.sweep", str(grid), "--out"]

    one = single([*args, str(tmp_path / "one")])
    assert one.returncode == 0, one.stderr[-2000:]
    two_devices = single([*args, str(tmp_path / "two_devices")], devices=2)
    assert two_devices.returncode == 0, two_devices.stderr[-2000:]
    codes, texts = run([*args, str(tmp_path / "two")], 2)
    assert codes == [0, 0], [t[1][-2000:] for t in texts]
    ref = _sweep_files(tmp_path / "one")
    assert len(ref) == 8 + 1  # 2 points x 2 policies x 2 seeds, and the table
    assert _sweep_files(tmp_path / "two_devices") == ref
    assert _sweep_files(tmp_path / "two") == ref
    assert "wrote" in texts[0][0] and "wrote" not in texts[1][0]  # process 0 alone writes


def _wait_for(path, limit_s):
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        if path.exists() and any(path.iterdir()):
            return True
        time.sleep(0.2)
    return False


@pytest.mark.slow
@pytest.mark.parametrize("fault", ["kill", "hang"])
def test_a_peer_lost_mid_run_ends_the_other_within_the_timeout(tmp_path, fault):
    """Process 1 is killed (or stopped) after process 0 saved its first item: process 0 ends within
    --dist-timeout with one line and exit code 1, and writes no table."""
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps({**GRID, "seeds": list(range(20))}))
    timeout_s = 20
    procs = start(
        ["-m", "semuav_jax.cli.sweep", str(grid), "--out", str(tmp_path / "out")], 2, timeout_s=timeout_s, logs=tmp_path
    )
    try:
        assert _wait_for(tmp_path / "out" / "items", 240), (tmp_path / "p0.err").read_text()[-2000:]
        os.kill(procs[1].pid, signal.SIGKILL if fault == "kill" else signal.SIGSTOP)
        t0 = time.monotonic()
        code = procs[0].wait(timeout_s + 15)
        wall = time.monotonic() - t0
    finally:
        if fault == "hang":
            os.kill(procs[1].pid, signal.SIGCONT)
        end_all(procs)
    err = (tmp_path / "p0.err").read_text().strip().splitlines()
    print(f"{fault}: process 0 ended {wall:.1f} s after the fault: {err[-1]}")
    assert code == 1, err[-5:]
    assert wall <= timeout_s
    assert "error:" in err[-1] and ("peer process 1" in err[-1] or "distributed run stopped" in err[-1])
    assert not (tmp_path / "out" / "sweep.csv").exists() and not (tmp_path / "out" / "sweep.json").exists()


@pytest.mark.slow
def test_sweep_items_of_two_invocations_merge_to_one_invocation(tmp_path):
    """An --item run, then a run of the rest (separate invocations), give the files of one plain run."""
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps({**GRID, "policies": ["greedy"], "params": {"B": [5e3, 25e3], "K": 40}}))
    args = ["-m", "semuav_jax.cli.sweep", str(grid), "--out"]
    assert single([*args, str(tmp_path / "whole")]).returncode == 0
    count = single([*args, str(tmp_path / "parts"), "--count"])
    assert count.stdout.strip() == "4"  # 2 points x 1 policy x 2 seeds
    first = single([*args, str(tmp_path / "parts"), "--item", "2"])
    assert first.returncode == 0, first.stderr[-2000:]
    missing = single([*args, str(tmp_path / "parts"), "--merge"])
    assert missing.returncode == 2 and "3 of 4 items are not done" in missing.stderr
    rest = single([*args, str(tmp_path / "parts")])  # runs the 3 items not done, skips item 2
    assert rest.returncode == 0 and "3 of 4 items run" in rest.stdout, rest.stderr[-2000:]
    assert _sweep_files(tmp_path / "parts") == _sweep_files(tmp_path / "whole")
    again = single([*args, str(tmp_path / "parts"), "--item", "1"])
    assert "(done before)" in again.stdout


EVAL = [
    str(ROOT / "eval.py"),
    "--quick",
    "--layouts",
    "6",
    "--validation-layouts",
    "4",
    "--bandwidths",
    "25000",
    "--velocities",
    "8.9",
    "--workers",
    "1",
]

# runs a script (argv[1]) recording every write, rename, removal or folder made under --out in a JSON
# list (argv[2] with the process id: PATH.I.json), so a test sees which process touched the folder
WATCHED = textwrap.dedent(
    """
    import atexit, json, os, runpy, sys
    log, script, args = sys.argv[2], sys.argv[1], sys.argv[3:]
    out = os.path.realpath(args[args.index("--out") + 1])
    me = args[args.index("--process-id") + 1] if "--process-id" in args else "0"
    seen = []
    WRITE = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND
    CHANGE = ("os.rename", "os.remove", "os.mkdir", "os.rmdir", "os.truncate", "os.link", "os.symlink", "shutil.rmtree")

    def under(p):
        if isinstance(p, (str, bytes, os.PathLike)):
            p = os.path.realpath(os.fsdecode(p))
            return p == out or p.startswith(out + os.sep)
        return False

    def hook(event, a):
        if (event == "open" and a[2] & WRITE and under(a[0])) or (event in CHANGE and any(map(under, a[:2]))):
            seen.append([event, *map(str, a[:2])])

    sys.addaudithook(hook)
    atexit.register(lambda: open(f"{log}.{me}.json", "w").write(json.dumps(seen)))
    sys.argv = [script, *args]
    runpy.run_path(script, run_name="__main__")
    """
)


def _fig2(out):
    r = json.loads((out / "fig2.json").read_text())
    return {k: v for k, v in r.items() if k not in ("devices", "train_s", "eval_s")}


def _saved_steps(out):
    return {p.name: p.read_bytes() for p in sorted((out / "stages").glob("*.msgpack"))}


@pytest.fixture(scope="module")
def eval_one(tmp_path_factory):
    out = tmp_path_factory.mktemp("eval") / "one"
    one = single([*EVAL, "--out", str(out)], limit_s=1800)
    assert one.returncode == 0, one.stderr[-2000:]
    return out


@pytest.mark.slow
def test_eval_quick_is_the_same_with_2_host_devices(eval_one, tmp_path):
    two = single([*EVAL, "--out", str(tmp_path / "two")], devices=2, limit_s=1800)
    assert two.returncode == 0, two.stderr[-2000:]
    assert json.loads((tmp_path / "two" / "fig2.json").read_text())["devices"] == 2
    assert _fig2(tmp_path / "two") == _fig2(eval_one) and _saved_steps(tmp_path / "two") == _saved_steps(eval_one)


@pytest.mark.slow
@pytest.mark.parametrize("devices", [1, 2])
def test_eval_quick_is_the_same_on_2_processes(eval_one, tmp_path, devices):
    """eval.py --quick on a reduced grid, 2 processes of 1 or 2 devices: the same fig2.json, fig2.md and
    saved steps (bytes) as 1 process of 1 device; process 1 writes nothing in --out. Run again
    (--overwrite): both processes find every step saved (process 1 through its read-only view of
    the folder) and give the same files."""
    out = tmp_path / "two"
    cmd = ["-c", WATCHED, EVAL[0], str(tmp_path / "writes"), *EVAL[1:], "--out", str(out)]
    codes, texts = run(cmd, 2, limit_s=1800, devices=devices)
    assert codes == [0, 0], [t[1][-2000:] for t in texts]
    assert _fig2(out) == _fig2(eval_one)
    assert (out / "fig2.md").read_text() == (eval_one / "fig2.md").read_text()
    steps = _saved_steps(eval_one)
    assert len(steps) == 7 and _saved_steps(out) == steps
    writes = [json.loads((tmp_path / f"writes.{i}.json").read_text()) for i in (0, 1)]
    assert writes[1] == [] and len(writes[0]) > 10, writes
    assert "wrote" in texts[0][0] and "wrote" not in texts[1][0]

    codes, texts = run([*cmd, "--overwrite"], 2, limit_s=900, devices=devices)
    assert codes == [0, 0], [t[1][-2000:] for t in texts]
    for out_text, err in texts:  # the 7 steps loaded in both processes, only the paths recomputed
        assert out_text.count("(saved before)") == 7, (out_text[-2000:], err[-2000:])
    assert _fig2(out) == _fig2(eval_one) and _saved_steps(out) == steps
    assert json.loads((tmp_path / "writes.1.json").read_text()) == []


@pytest.mark.slow
def test_train_on_2_processes_writes_the_weights_of_1(tmp_path, curves):
    """train.py on 2 processes (each trains every seed, process 0 writes): the files of 1 process."""
    from semuav_jax.curves import save_curves

    c = str(save_curves(tmp_path / "curves.npz", curves, {"source": "synthetic"}))
    cmd = [
        str(ROOT / "train.py"),
        "--curves",
        c,
        "--seeds",
        "3",
        "--num-envs",
        "4",
        "--steps-per-chunk",
        "5",
        "--total-steps",
        "80",
        "--learning-starts",
        "32",
        "--batch-size",
        "8",
        "--segments",
        "2",
        "--eval-episodes",
        "0",
        "--out",
    ]
    one = single([*cmd, str(tmp_path / "one")])
    assert one.returncode == 0, one.stderr[-2000:]
    codes, texts = run([*cmd, str(tmp_path / "two")], 2, limit_s=600)
    assert codes == [0, 0], [t[1][-2000:] for t in texts]
    for name in ("model.msgpack", "checkpoint.msgpack", "metrics.csv"):
        assert (tmp_path / "two" / name).read_bytes() == (tmp_path / "one" / name).read_bytes(), name
