"""Training and test images for the DeepJSCC (MODEL.md section 9); nothing is downloaded.

The built-in data are the colour photos that ship inside the scikit-image and scikit-learn
wheels. Whole photos are held out for the test set, so no test crop overlaps a training photo.
Training crops are random 32x32 windows (with horizontal flips and colour-channel permutations)
of each training photo at scales 1, 1/2 and 1/4; test crops are fixed non-overlapping windows of the held-out photos.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

try:
    from numpy._core.multiarray import _reconstruct
except ImportError:  # numpy < 2
    from numpy.core.multiarray import _reconstruct

CROP = 32
SCALES = (1, 2, 4)
SKIMAGE_TRAIN = (
    "astronaut.png",
    "coffee.png",
    "hubble_deep_field.jpg",
    "ihc.png",
    "motorcycle_left.png",
    "motorcycle_right.png",
    "retina.jpg",
    "rocket.jpg",
)
SKLEARN_TRAIN = ("china.jpg",)
SKIMAGE_TEST = ("chelsea.png",)
SKLEARN_TEST = ("flower.jpg",)
TEST_SCALES = (1, 2)
TEST_CROPS_PER_PHOTO_SCALE = 16
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")


def _skimage_dir() -> Path:
    import skimage

    return Path(skimage.__file__).parent / "data"


def _sklearn_dir() -> Path:
    import sklearn.datasets

    return Path(sklearn.datasets.__file__).parent / "images"


def _read_rgb(path: Path) -> np.ndarray:
    """Read an image file as uint8 RGB (H, W, 3); ValueError if unreadable."""
    from skimage import io

    try:
        im = np.asarray(io.imread(path))
    except Exception as e:
        raise ValueError(f"cannot read image {path}: {type(e).__name__}: {e}") from e
    if im.ndim == 2:
        im = np.repeat(im[..., None], 3, axis=-1)
    if im.ndim != 3 or im.shape[-1] not in (3, 4):
        raise ValueError(f"{path}: expected a grayscale, RGB or RGBA image, got shape {im.shape}")
    im = im[..., :3]
    if im.dtype != np.uint8:
        im = np.clip(np.asarray(im, np.float64) * (255.0 if im.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    return im


def _builtin_paths(skimage_names: Iterable[str], sklearn_names: Iterable[str]) -> list[Path]:
    paths = [_skimage_dir() / n for n in skimage_names] + [_sklearn_dir() / n for n in sklearn_names]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise ValueError(f"built-in photos missing from the installed wheels: {missing}")
    return paths


def _pyramid(im: np.ndarray, scales: Sequence[int] = SCALES) -> list[np.ndarray]:
    """float32 [0, 1] versions of ``im`` downscaled by each factor (area averaging)."""
    x = im.astype(np.float32) / 255.0
    out = []
    for s in scales:
        h, w = (x.shape[0] // s) * s, (x.shape[1] // s) * s
        y = x[:h, :w].reshape(h // s, s, w // s, s, 3).mean(axis=(1, 3))
        if min(y.shape[:2]) >= CROP:
            out.append(y)
    return out


def builtin_train_photos() -> list[np.ndarray]:
    """Training photos (all scales) from the scikit-image / scikit-learn wheels."""
    return [p for path in _builtin_paths(SKIMAGE_TRAIN, SKLEARN_TRAIN) for p in _pyramid(_read_rgb(path))]


def builtin_test_set(seed: int = 0) -> tuple[np.ndarray, list[str]]:
    """Held-out test crops (N, 32, 32, 3) float32 in [0, 1] and their names.

    From each held-out photo at each test scale, ``TEST_CROPS_PER_PHOTO_SCALE`` cells of the
    non-overlapping 32x32 grid are drawn without replacement with a fixed seed.
    """
    rng = np.random.default_rng(seed)
    images, names = [], []
    for path in _builtin_paths(SKIMAGE_TEST, SKLEARN_TEST):
        im = _read_rgb(path)
        for s, y in zip(TEST_SCALES, _pyramid(im, TEST_SCALES)):
            rows, cols = y.shape[0] // CROP, y.shape[1] // CROP
            cells = rng.choice(rows * cols, size=TEST_CROPS_PER_PHOTO_SCALE, replace=False)
            for c in sorted(cells):
                r, q = divmod(int(c), cols)
                images.append(y[r * CROP : (r + 1) * CROP, q * CROP : (q + 1) * CROP])
                names.append(f"{path.stem}@1/{s}:r{r}c{q}")
    return np.stack(images).astype(np.float32), names


def folder_photos(folder: str | os.PathLike) -> list[np.ndarray]:
    """All readable images in ``folder`` (non-recursive) as float32 photos at all scales."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"image folder {folder} does not exist or is not a directory")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise ValueError(f"image folder {folder} holds no image files ({', '.join(IMAGE_SUFFIXES)})")
    photos = [p for f in files for p in _pyramid(_read_rgb(f))]
    if not photos:
        raise ValueError(f"no image in {folder} is at least {CROP}x{CROP} pixels")
    return photos


# The only globals a CIFAR-10 python batch references (numpy arrays, pickled by numpy 1 or 2).
CIFAR_GLOBALS = {
    ("numpy.core.multiarray", "_reconstruct"): _reconstruct,
    ("numpy._core.multiarray", "_reconstruct"): _reconstruct,
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
}


class _NotCifar(Exception):
    pass


class _CifarUnpickler(pickle.Unpickler):
    """Unpickler that builds nothing but builtins and numpy arrays: ``pickle.load`` of a crafted
    file runs arbitrary code, through the globals it names."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) not in CIFAR_GLOBALS:
            raise _NotCifar(f"it references {module}.{name}")
        return CIFAR_GLOBALS[module, name]


def cifar10_images(path: str | os.PathLike, test: bool = False) -> np.ndarray:
    """CIFAR-10 from its python batches in ``path`` (data_batch_1..5 or test_batch) as (N, 32, 32, 3).

    A batch may reference no global outside :data:`CIFAR_GLOBALS`, so a crafted file cannot run code.
    """
    path = Path(path)
    names = ["test_batch"] if test else [f"data_batch_{i}" for i in range(1, 6)]
    files = [path / n for n in names]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise ValueError(f"CIFAR-10 python batches not found: {missing} (expected cifar-10-batches-py layout)")
    arrays = []
    for f in files:
        try:
            with open(f, "rb") as fh:
                d = _CifarUnpickler(fh, encoding="bytes").load()
            arrays.append(np.asarray(d[b"data"], np.uint8).reshape(-1, 3, 32, 32).transpose(0, 2, 3, 1))
        except _NotCifar as e:
            raise ValueError(f"{f} is not a CIFAR-10 batch: {e}") from None
        except Exception as e:
            raise ValueError(f"{f}: not a readable CIFAR-10 python batch ({type(e).__name__}: {e})") from e
    return np.concatenate(arrays).astype(np.float32) / 255.0


PERMUTATIONS = np.array([[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]])


def dead_leaves(n: int, rng: np.random.Generator, disks: int = 48) -> np.ndarray:
    """``n`` synthetic 32x32 dead-leaves images: ``disks`` occluding disks of uniform random
    colour, radii with density ~ r^-3 on [1, 24] px (the scale-invariant model of natural-image
    statistics, Lee, Mumford & Huang 2001), on a random background."""
    yy, xx = np.mgrid[:CROP, :CROP].astype(np.float32)
    u = rng.random((n, disks))
    r = 1.0 / np.sqrt(1.0 - u * (1.0 - 1.0 / 24.0**2))
    centre = rng.uniform(-8, CROP + 8, size=(n, disks, 2)).astype(np.float32)
    colour = rng.random((n, disks, 3)).astype(np.float32)
    out = np.repeat(rng.random((n, 1, 1, 3)).astype(np.float32), CROP, axis=1).repeat(CROP, axis=2)
    for j in range(disks):
        inside = (yy - centre[:, j, 0, None, None]) ** 2 + (xx - centre[:, j, 1, None, None]) ** 2 < r[
            :, j, None, None
        ] ** 2
        out = np.where(inside[..., None], colour[:, j, None, None, :], out)
    return out


def sample_batch(photos: list[np.ndarray], batch: int, rng: np.random.Generator, synthetic: float = 0.0) -> np.ndarray:
    """A batch of random 32x32 crops, photo chosen uniformly, with random horizontal flips and,
    for half of the crops, a random permutation of the colour channels (the few training photos
    hold little green; without it green test crops decode blue). With ``synthetic`` > 0, that
    fraction of the batch is replaced by :func:`dead_leaves` images."""
    out = np.empty((batch, CROP, CROP, 3), np.float32)
    which = rng.integers(len(photos), size=batch)
    flips = rng.random(batch) < 0.5
    perms = PERMUTATIONS[np.where(rng.random(batch) < 0.5, 0, rng.integers(1, 6, size=batch))]
    for b in range(batch):
        p = photos[which[b]]
        r = rng.integers(p.shape[0] - CROP + 1)
        c = rng.integers(p.shape[1] - CROP + 1)
        crop = p[r : r + CROP, c : c + CROP]
        out[b] = (crop[:, ::-1] if flips[b] else crop)[..., perms[b]]
    n_syn = int(round(synthetic * batch))
    if n_syn:
        out[:n_syn] = dead_leaves(n_syn, rng)
    return out
