"""OME-Zarr against the Python OME-Zarr stack: a store the `ome-zarr` package writes from a
shared NIfTI (NGFF 0.4 on Zarr v2 and 0.5 on Zarr v3) reads in volao with the NIfTI's
dims, spacing, orientation and statistics, and the right dims at every level; a store
`volao convert` writes reads in `ome_zarr`/`zarr` as the NIfTI's array, axes (z, y, x),
with the right scales."""

from __future__ import annotations

import json

import nibabel as nib
import numcodecs
import numpy as np
import pytest
import zarr
from ome_zarr.format import FormatV04, FormatV05
from ome_zarr.io import parse_url
from ome_zarr.reader import Reader
from ome_zarr.writer import write_image

import volao
from conftest import run_cli

AVG152 = "nifti/avg152T1_LR_nifti.nii.gz"  # 91×109×91 u8, 2 mm, LAS

# RFC-4 anatomical orientation: the direction in which an axis's coordinate grows.
RFC4 = {"R": "left-to-right", "L": "right-to-left", "A": "posterior-to-anterior",
        "P": "anterior-to-posterior", "S": "inferior-to-superior", "I": "superior-to-inferior"}
# Sign of the RAS world axis each code runs along.
SIGN = {"R": 1.0, "L": -1.0, "A": 1.0, "P": -1.0, "S": 1.0, "I": -1.0}
WORLD = {"R": 0, "L": 0, "A": 1, "P": 1, "S": 2, "I": 2}


def info(cli, store, *extra):
    return json.loads(run_cli(cli, "info", store, "--json", *extra).stdout)


def ome_fields(attrs: dict) -> dict:
    """The OME-Zarr fields of a group's attributes, 0.4 (top level) or 0.5 (``ome``)."""
    return attrs["ome"] if "ome" in attrs else attrs


def write_with_ome_zarr(img, path, fmt):
    """The NIfTI's voxels as a (z, y, x) pyramid written by `ome_zarr.writer`, with scale
    from the header's spacing; then its translation and RFC-4 orientation added to the
    metadata (ome-zarr's `write_image` takes neither)."""
    data = np.ascontiguousarray(np.asanyarray(img.dataobj).T)  # (x, y, z) -> (z, y, x)
    sx, sy, sz = (float(v) for v in img.header.get_zooms()[:3])
    v2 = fmt.version == "0.4"
    root = zarr.open_group(str(path), mode="w", zarr_format=2 if v2 else 3)
    # Zarr v2 stores as zarr-python 2 wrote them (most NGFF 0.4 data): Blosc/LZ4 with
    # shuffle, numcodecs' default then; Zarr v3: zarr-python's default (zstd).
    options = {"compressor": numcodecs.Blosc(cname="lz4", shuffle=numcodecs.Blosc.SHUFFLE)} if v2 else None
    write_image(data, root, fmt=fmt, axes="zyx",
                scale={"z": sz, "y": sy, "x": sx},
                axes_units={"z": "millimeter", "y": "millimeter", "x": "millimeter"},
                scale_factors=[{"z": 2, "y": 2, "x": 2}, {"z": 4, "y": 4, "x": 4}],
                storage_options=options)
    codes = nib.aff2axcodes(img.affine)  # per voxel axis x, y, z
    origin = img.affine[:3, 3]
    attrs = root.attrs.asdict()
    ms = ome_fields(attrs)["multiscales"][0]
    for axis, code in zip(ms["axes"], reversed(codes)):  # axes are z, y, x
        axis["orientation"] = {"type": "anatomical", "value": RFC4[code]}
    # Coordinate along a voxel axis = index · scale + translation, growing the way its
    # orientation says: the NIfTI origin in those coordinates.
    t0 = [SIGN[c] * origin[WORLD[c]] for c in reversed(codes)]
    for ds in ms["datasets"]:
        for t in ds["coordinateTransformations"]:
            if t["type"] == "translation":
                t["translation"] = [a + b for a, b in zip(t["translation"], t0)]
    root.attrs.update(attrs)
    return data


@pytest.mark.parametrize("fmt", [FormatV04(), FormatV05()], ids=["ngff0.4-zarr2", "ngff0.5-zarr3"])
def test_store_written_by_ome_zarr_reads_in_volao(data, volao_cli, tmp_path, fmt):
    img = nib.load(data / AVG152)
    store = tmp_path / "avg152.ome.zarr"
    zyx = write_with_ome_zarr(img, store, fmt)
    xyz = zyx.T

    j = info(volao_cli, store)
    assert j["format"].startswith(f"OME-Zarr {fmt.version} (Zarr v{2 if fmt.version == '0.4' else 3})")
    assert j["dims"] == list(img.shape)
    assert j["spacing_mm"] == pytest.approx([float(v) for v in img.header.get_zooms()])
    assert j["orientation"] == "".join(nib.aff2axcodes(img.affine)) == "LAS"
    assert np.allclose(np.array(j["affine"]), img.affine[:3], atol=1e-6)
    assert j["voxel_type"] == "u8"
    assert j["stats"]["min"] == xyz.min() and j["stats"]["max"] == xyz.max()
    assert j["stats"]["mean"] == pytest.approx(float(xyz.mean()), rel=1e-9)

    # Every level: volao's dims are the array's shape reversed, its spacing the scale.
    group = zarr.open_group(str(store), mode="r")
    datasets = ome_fields(group.attrs.asdict())["multiscales"][0]["datasets"]
    assert len(j["levels"]) == len(datasets) == 3
    for level, ds in zip(j["levels"], datasets):
        assert level["path"] == ds["path"]
        assert level["dims"] == list(group[ds["path"]].shape[::-1])
        scale = [t for t in ds["coordinateTransformations"] if t["type"] == "scale"][0]["scale"]
        assert level["spacing_mm"] == pytest.approx(scale[::-1])

    # Level 2 read as a volume: its array, placed by its own transforms.
    j2 = info(volao_cli, store, "--level", "2")
    level2 = np.asarray(group[datasets[2]["path"]][:]).T
    assert j2["dims"] == list(level2.shape)
    assert j2["stats"]["max"] == level2.max()
    assert j2["stats"]["mean"] == pytest.approx(float(level2.mean()), rel=1e-9)

    # The Python module reads the same store.
    v = volao.load(store)
    assert v.dims == img.shape and v.dtype == "uint8"
    assert np.array_equal(v.array, xyz)
    assert np.allclose(v.affine, img.affine, atol=1e-6)
    assert volao.load(store, level=1).dims == tuple(group[datasets[1]["path"]].shape[::-1])


def test_store_written_by_volao_reads_in_ome_zarr(data, volao_cli, tmp_path):
    src = data / AVG152
    img = nib.load(src)
    store = tmp_path / "avg152.ome.zarr"
    run_cli(volao_cli, "convert", src, store)

    reader = Reader(parse_url(str(store)))
    node = list(reader())[0]
    levels = [np.asarray(d) for d in node.data]
    assert [a["name"] for a in node.metadata["axes"]] == ["z", "y", "x"]
    # Level 0 is the NIfTI's array, axes reversed to (z, y, x), same dtype, every voxel.
    want = np.asanyarray(img.dataobj).T
    assert levels[0].dtype == want.dtype == np.uint8
    assert np.array_equal(levels[0], want)
    # The scales: the spacing (z, y, x) doubling per level; the shapes halving (ceil).
    zooms = [float(v) for v in img.header.get_zooms()][::-1]
    shape = list(want.shape)
    for k, (arr, transforms) in enumerate(zip(levels, node.metadata["coordinateTransformations"])):
        scale = [t for t in transforms if t["type"] == "scale"][0]["scale"]
        assert scale == pytest.approx([z * 2 ** k for z in zooms])
        assert list(arr.shape) == shape
        shape = [(n + 1) // 2 for n in shape]
    assert len(levels) == 2  # 91×109×91 → 46×55×46, whose longest edge is ≤ 64
    # Level 1 is the rounded 2×2×2 mean of level 0.
    padded = np.pad(want.astype(np.float64), [(0, n % 2) for n in want.shape], constant_values=np.nan)
    blocks = padded.reshape(46, 2, 55, 2, 46, 2)
    mean = np.nanmean(blocks, axis=(1, 3, 5))
    assert np.array_equal(levels[1], np.floor(mean + 0.5).astype(np.uint8))

    # zarr alone reads the RFC-4 orientation volao wrote: LAS for this file.
    group = zarr.open_group(str(store), mode="r")
    axes = group.attrs["ome"]["multiscales"][0]["axes"]
    assert [a["orientation"]["value"] for a in axes] == [
        "inferior-to-superior", "posterior-to-anterior", "right-to-left"]
    assert [a["unit"] for a in axes] == ["millimeter"] * 3
