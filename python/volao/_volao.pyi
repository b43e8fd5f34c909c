"""Type stubs of volao's native module (re-exported by ``volao``)."""

from __future__ import annotations

import os
from typing import Any, Callable, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from . import Image

PathLike = Union[str, "os.PathLike[str]"]
Progress = Callable[[str, int, int], Any]
"""``progress(stage, done, total)``: called while a file loads (bytes) and while AO is
computed (z-slices), at most once per percent."""

class VolaoError(Exception):
    """A volume, scene or GPU error, with the one-line message the volao CLI prints."""

class Volume:
    """A scalar volume: voxels as stored (x fastest), spacing in mm, the voxel-to-RAS
    affine."""

    def __init__(
        self,
        array: Any,
        spacing: Optional[Sequence[float]] = None,
        affine: Optional[npt.ArrayLike] = None,
    ) -> None:
        """A numpy array indexed ``[x, y, z]`` (C or Fortran order) of uint8, int8,
        uint16, int16, uint32, int32, float32 or float64, or a nibabel image (its data
        and affine). Without an affine the voxel axes are RAS scaled by ``spacing``
        (default 1 mm); with one, the spacing defaults to the affine's column lengths.

        Raises ``ValueError`` for an array that is not 3-D, ``TypeError`` for an
        unsupported dtype, ``VolaoError`` for an unusable affine."""
    @property
    def dims(self) -> Tuple[int, int, int]:
        """Voxel counts along x, y, z."""
    @property
    def spacing(self) -> Tuple[float, float, float]:
        """Voxel spacing in mm along x, y, z."""
    @property
    def dtype(self) -> str:
        """The numpy dtype name of the stored voxels (``int16``, ``float32``, …)."""
    @property
    def affine(self) -> npt.NDArray[np.float64]:
        """The 4×4 voxel-index → world (RAS+, mm) affine, as nibabel's ``img.affine``."""
    @property
    def array(self) -> np.ndarray:
        """The voxels as stored, shape ``(x, y, z)``, Fortran order; a copy per access."""
    @property
    def stats(self) -> dict:
        """``{min, max, mean, non_finite}`` over the physical values."""
    @property
    def scaling(self) -> Tuple[float, float]:
        """``(slope, inter)``: physical value = slope · stored + inter."""
    @property
    def path(self) -> Optional[str]:
        """The file it was read from, or None for a volume made from an array."""
    @property
    def format(self) -> Optional[str]:
        """The file format it was read from, or None."""
    def save(self, path: PathLike) -> None:
        """Writes the volume; the extension picks the format (.nii, .nii.gz, .pvm, .raw)."""
    def to_nibabel(self) -> Any:
        """A ``nibabel.Nifti1Image`` of the stored voxels and the affine."""

class Scene:
    """A reproducible view of a volume, with the fields of a volao scene file."""

    def __init__(self, volume: Union[Volume, np.ndarray, Any], **settings: Any) -> None:
        """The default scene of ``volume`` (TF preset by its value range, 800×800),
        changed by ``settings``: any scene file field (``transfer_function``,
        ``camera``, ``light``, ``render``, ``width``, ``height``,
        ``ambient_occlusion``, ``clip_shapes``, ``meshes``, ``segmentation``; dicts
        update the field), or the shorthands ``tf`` (preset name or points),
        ``window_level=(w, l)``, ``camera=(azimuth, elevation, distance)``, ``mode``,
        ``shading``, ``background``, ``shadows``, ``step``, ``ambient``, ``ao``
        (method), ``rays``, ``samples``, ``ortho``, ``light_direction``, ``labels``,
        ``label_table``, ``segment`` (``volao render --segment`` specs)."""
    @staticmethod
    def load(path: PathLike) -> Scene:
        """Reads a scene file (paths relative to it); its volume loads at first use."""
    def set(self, **settings: Any) -> None:
        """Changes settings, with the keywords of ``Scene(volume, **settings)``."""
    def save(self, path: PathLike) -> None:
        """Writes the scene file; ``volao render`` of it gives ``render()``'s bytes."""
    def render(
        self,
        width: Optional[int] = None,
        height: Optional[int] = None,
        progress: Optional[Progress] = None,
    ) -> Image:
        """Renders into a numpy ``(H, W, 4)`` uint8 ``Image`` (GIL released)."""
    @property
    def volume(self) -> Volume:
        """The scene's volume (read from its file at first use)."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    def to_json(self) -> str:
        """The scene as scene-file JSON (paths absolute)."""

def load(
    path: PathLike,
    frame: Optional[int] = None,
    series: Optional[str] = None,
    progress: Optional[Progress] = None,
    level: Optional[int] = None,
) -> Volume:
    """Reads a volume file (NIfTI, Analyze, NRRD, MGH, DICOM folder, OME-Zarr store,
    PVM, raw with a sidecar); the GIL is released while it reads. ``level``: an
    OME-Zarr store's multiscale level (0 = full resolution). ``FileNotFoundError`` for
    a missing file, ``VolaoError`` for one volao cannot read."""

def ambient_occlusion(
    volume: Union[Volume, np.ndarray, Any],
    method: str = "lao",
    *,
    tf: Union[None, str, Mapping[str, Any]] = None,
    clip: Optional[Sequence[Mapping[str, Any]]] = None,
    visible_only: bool = False,
    cpu: bool = False,
    progress: Optional[Progress] = None,
    **settings: Any,
) -> npt.NDArray[np.float32]:
    """The ambient factor A(x) in [0, 1] of every voxel, float32 of shape ``(x, y, z)``:
    the values ``volao ao`` writes for the same method, parameters (``rays``,
    ``samples``, ``vao``, ``radius``, …: a scene file's ``ambient_occlusion`` fields)
    and transfer function."""

def adapter() -> str:
    """The adapter volao renders on in this process, in words."""

def encode_png(array: np.ndarray) -> bytes:
    """The PNG file of an RGBA uint8 ``(H, W, 4)`` array."""

def save_png(array: np.ndarray, path: PathLike) -> None:
    """Writes an RGBA uint8 ``(H, W, 4)`` array as PNG."""

def private_runtime_dir() -> Optional[str]:
    """A private runtime folder for Mesa when ``XDG_RUNTIME_DIR`` is unset, else None."""
