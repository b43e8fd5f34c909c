"""volao from Python: load volumes, render scenes and compute ambient-occlusion volumes.

A thin layer over the Rust library that the ``volao`` command line uses, so an image
rendered here has the bytes of ``volao render`` of the same scene::

    import volao
    ct = volao.load("cranium-ct.nrrd")
    scene = volao.Scene(ct, tf="ct-bone", ao="lao", rays=14, width=512, height=512)
    image = scene.render()          # numpy (512, 512, 4) uint8
    image.save("cranium.png")

Notes and warnings go to the ``volao`` logger (``logging.getLogger("volao")``), never to
stdout; long calls take an optional ``progress(stage, done, total)`` callback. One GPU
device is opened per process, at the first render, and reused.
"""

from __future__ import annotations

import logging
import os

import numpy as np

from ._volao import (
    Scene,
    Volume,
    VolaoError,
    adapter,
    ambient_occlusion,
    load,
)
from . import _volao, cohort

__all__ = [
    "Image",
    "Scene",
    "Volume",
    "VolaoError",
    "adapter",
    "cohort",
    "ambient_occlusion",
    "load",
]

logging.getLogger("volao").addHandler(logging.NullHandler())

# Mesa's window-system layer prints an error on every device opened without a runtime
# folder, even headless; give it the private one the volao CLI uses. Set before any
# device exists (devices open at the first render).
_runtime = _volao.private_runtime_dir()
if _runtime is not None:
    os.environ["XDG_RUNTIME_DIR"] = os.fspath(_runtime)


class Image(np.ndarray):
    """A rendered image: a numpy ``(H, W, 4)`` uint8 array (straight alpha, rows from the
    top) that shows itself in Jupyter and saves as the PNG ``volao render`` writes.

    ``info`` holds how it was rendered: ``device``, ``ao_seconds``, ``downsampled``,
    ``notes``.
    """

    info: dict

    def __new__(cls, array, info=None):
        obj = np.asarray(array, dtype=np.uint8).view(cls)
        obj.info = dict(info or {})
        return obj

    def __array_finalize__(self, obj):
        self.info = getattr(obj, "info", {})

    def _repr_png_(self) -> bytes:
        return _volao.encode_png(np.ascontiguousarray(self.view(np.ndarray)))

    def save(self, path: str | os.PathLike) -> None:
        """Writes the image as PNG (the bytes ``volao render`` writes for it)."""
        _volao.save_png(np.ascontiguousarray(self.view(np.ndarray)), os.fspath(path))
