"""semuav-sweep, eval.py and train.py on 2 processes or 2 host devices write the files of 1 (docs/scaling.md)."""

import json
import textwrap

import pytest
from conftest import GRID, TRAIN_TINY
from multiprocess import ROOT, run, single


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
    cmd = [str(ROOT / "train.py"), *TRAIN_TINY, "--curves", c, "--seeds", "3", "--out"]
    one = single([*cmd, str(tmp_path / "one")])
    assert one.returncode == 0, one.stderr[-2000:]
    codes, texts = run([*cmd, str(tmp_path / "two")], 2, limit_s=600)
    assert codes == [0, 0], [t[1][-2000:] for t in texts]
    for name in ("model.msgpack", "checkpoint.msgpack", "metrics.csv"):
        assert (tmp_path / "two" / name).read_bytes() == (tmp_path / "one" / name).read_bytes(), name
