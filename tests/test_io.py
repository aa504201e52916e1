"""semuav_jax.io.save_figure: a figure written atomically in the format of its suffix, then closed."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from semuav_jax import io  # noqa: E402


@pytest.mark.parametrize("suffix, magic", [(".png", b"\x89PNG"), (".pdf", b"%PDF"), (".svg", b"<?xml")])
def test_save_figure_writes_the_suffix_format_and_closes(tmp_path, suffix, magic):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    out = io.save_figure(fig, tmp_path / "sub" / f"f{suffix}", layout=False)
    assert out.read_bytes().startswith(magic) and not plt.fignum_exists(fig.number)
    assert [p.name for p in out.parent.iterdir()] == [out.name]  # no temporary file left


def test_an_interrupted_save_keeps_the_previous_figure(tmp_path, monkeypatch):
    path = tmp_path / "f.png"
    path.write_bytes(b"old")
    fig = plt.figure()

    def kill(*a):
        raise KeyboardInterrupt

    monkeypatch.setattr(io.os, "replace", kill)
    with pytest.raises(KeyboardInterrupt):
        io.save_figure(fig, path)
    assert path.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["f.png"]
