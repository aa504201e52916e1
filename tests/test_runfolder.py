"""Output folders (semuav_jax.runfolder): ownership marker, manifest-only clean-up, the lock (two
real processes), and how train.py, eval.py and jscc use them (docs/reliability.md)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import TRAIN_TINY

from semuav_jax import runfolder
from semuav_jax.runfolder import LOCK, MARKER, FolderError, RunFolder

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def test_marker_is_written_first_and_lists_what_was_written(tmp_path):
    f = RunFolder.claim(tmp_path / "o", "test")
    marker = json.loads((tmp_path / "o" / MARKER).read_text())
    assert marker["format"] == runfolder.FORMAT and len(marker["run_id"]) == 16 and marker["files"] == []
    f.write("a.txt", b"1")
    f.write("sub/b.txt", b"2")
    assert json.loads((tmp_path / "o" / MARKER).read_text())["files"] == ["a.txt", "sub/b.txt"]
    assert (tmp_path / "o" / LOCK).is_file()
    f.release()
    assert not (tmp_path / "o" / LOCK).exists()
    again = RunFolder.claim(tmp_path / "o", "test", overwrite=True)
    assert again.run_id != marker["run_id"] and again.files == []
    again.release()


def test_overwrite_removes_only_listed_files(tmp_path):
    f = RunFolder.claim(tmp_path, "test")
    f.write("config.json", b"ours")
    f.write("stages/x.msgpack", b"ours")
    (tmp_path / "metrics.csv").write_text("the user's")  # a run file's name, never written by us
    (tmp_path / "stages" / "notes.txt").write_text("the user's")
    f.release()
    RunFolder.claim(tmp_path, "test", overwrite=True).release()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([MARKER, "metrics.csv", "stages"])
    assert [p.name for p in (tmp_path / "stages").iterdir()] == ["notes.txt"]


def test_a_folder_without_our_marker_that_holds_anything_is_refused(tmp_path):
    (tmp_path / "config.json").write_text("the user's")
    for overwrite in (False, True):
        with pytest.raises(FolderError, match="did not write .*config.json"):
            RunFolder.claim(tmp_path, "test", overwrite=overwrite)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["config.json"]  # not even a lock was written
    with pytest.raises(FolderError, match="is a train folder"):
        f = RunFolder.claim(tmp_path / "t", "train")
        f.release()
        RunFolder.claim(tmp_path / "t", "eval")


def test_adopt_accepts_a_folder_of_only_known_names(tmp_path):
    (tmp_path / "checkpoint.msgpack").write_bytes(b"x")
    f = RunFolder.claim(tmp_path, "test", adopt=("checkpoint.msgpack", "config.json"))
    assert f.files == ["checkpoint.msgpack"]
    f.release()


def test_temporaries_of_listed_files_and_of_the_marker_are_removed(tmp_path):
    f = RunFolder.claim(tmp_path, "test")
    f.write("a.bin", b"1")
    f.release()
    for n in ("a.bin.k1ll3d00.tmp", f"{MARKER}.k1ll3d00.tmp", "b.bin.k1ll3d00.tmp", "notes.tmp"):
        (tmp_path / n).write_bytes(b"half")
    RunFolder.claim(tmp_path, "test").release()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([MARKER, "a.bin", "b.bin.k1ll3d00.tmp", "notes.tmp"])
    fresh = tmp_path / "fresh"  # killed while writing its first marker: still ours to take
    fresh.mkdir()
    (fresh / f"{MARKER}.k1ll3d00.tmp").write_bytes(b"half")
    RunFolder.claim(fresh, "test").release()
    assert [p.name for p in fresh.iterdir()] == [MARKER]


HOLD = """
import sys
from semuav_jax.runfolder import RunFolder
f = RunFolder.claim(sys.argv[1], sys.argv[2])
print("ready", flush=True)
sys.stdin.readline()
f.release()
"""


def _holder(folder, kind="test"):
    p = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(folder), kind],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=ROOT,
    )
    assert p.stdout.readline().strip() == "ready"
    return p


def test_a_second_writer_is_refused_naming_the_holder(tmp_path):
    p = _holder(tmp_path)
    try:
        with pytest.raises(FolderError, match=f"in use by another run \\(pid {p.pid} on "):
            RunFolder.claim(tmp_path, "test")
    finally:
        p.communicate("\n", timeout=60)
    RunFolder.claim(tmp_path, "test").release()  # released when the holder ended


def test_a_stale_lock_of_a_killed_process_is_taken_over(tmp_path):
    p = _holder(tmp_path)
    p.kill()  # SIGKILL: the lock file stays
    p.wait(timeout=60)
    assert (tmp_path / LOCK).is_file()
    RunFolder.claim(tmp_path, "test").release()


def _train(*args, timeout=600):
    return subprocess.run(
        [sys.executable, str(ROOT / "train.py"), *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
        env=ENV,
        timeout=timeout,
    )


@pytest.mark.slow
def test_train_overwrite_and_resume_refused_while_a_run_holds_the_folder(tmp_path):
    """Two real processes: a train.py run folder held by a running job; train.py --overwrite and
    --resume on it exit 2 with one line naming the holder and change nothing."""
    from semuav_jax.cli.train import load_run_config, parse_args
    from semuav_jax.cli.train_folder import prepare_folder

    out = tmp_path / "r"
    args = parse_args([*TRAIN_TINY, "--out", str(out)])
    prepare_folder(args, load_run_config(args)).release()  # a run stopped before its first checkpoint
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    p = _holder(out, "train.py run")
    try:
        for flag in ("--overwrite", "--resume"):
            res = _train(*TRAIN_TINY, "--out", str(out), flag)
            assert res.returncode == 2 and f"pid {p.pid}" in res.stderr and res.stderr.count("\n") == 1, res.stderr
    finally:
        p.communicate("\n", timeout=60)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_train_refuses_to_overwrite_the_users_run_named_files(tmp_path, capsys):
    from semuav_jax.cli.train import main

    out = tmp_path / "u"
    out.mkdir()
    (out / "config.json").write_text("my config")
    (out / "metrics.csv").write_text("my metrics")
    assert main([*TRAIN_TINY, "--out", str(out), "--overwrite"]) == 2
    assert "did not write" in capsys.readouterr().err
    assert (out / "config.json").read_text() == "my config" and sorted(p.name for p in out.iterdir()) == [
        "config.json",
        "metrics.csv",
    ]


def test_a_run_stopped_before_its_first_checkpoint_is_restartable(tmp_path):
    """The folder a kill before the first checkpoint leaves (marker + config.json) is accepted by
    --resume (from chunk 0) and by the same command again."""
    from semuav_jax.cli.train import load_run_config, parse_args
    from semuav_jax.cli.train_folder import prepare_folder

    out = tmp_path / "r"
    args = parse_args([*TRAIN_TINY, "--out", str(out)])
    cfg = load_run_config(args)
    prepare_folder(args, cfg).release()
    again = parse_args([*TRAIN_TINY, "--out", str(out)])
    prepare_folder(again, load_run_config(again)).release()
    resume = parse_args(["--out", str(out), "--resume"])
    assert load_run_config(resume) == cfg
    prepare_folder(resume, cfg).release()


def test_eval_refuses_a_folder_of_the_users_files(tmp_path, capsys):
    from semuav_jax.cli.eval import main

    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "stages").mkdir()
    (tmp_path / "stages" / "planner_at_5_kHz.msgpack").write_bytes(b"mine")
    for extra in ([], ["--overwrite"]):
        assert main(["--quick", "--out", str(tmp_path), *extra]) == 2
        assert "did not write" in capsys.readouterr().err
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == [
        "notes.txt",
        "stages",
        "stages/planner_at_5_kHz.msgpack",
    ]
