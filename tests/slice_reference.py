#!/usr/bin/env python3
"""Orientation reference for `volao slice`, from readers independent of volao.

Every slice `volao slice` writes (nearest sampling, a fixed window) must equal, pixel for
pixel, the same slice cut with numpy from the volume as nibabel (NIfTI, Analyze, and
dcm2niix's NIfTI of the DICOM series) or pynrrd (NRRD) reads it, on nibabel's
`as_closest_canonical` grid (RAS), turned to the reading-room convention:

  axial    rows A→P (anterior at the top),  columns R→L (radiological) or L→R (--neurological)
  coronal  rows S→I,                         columns R→L or L→R
  sagittal rows S→I,                         columns A→P

In-plane spacings that differ are resampled (nearest) to the finer one; an oblique
acquisition is resampled onto the patient's axes at its finest spacing (or shown in its
own planes with --acquisition-plane, which is `as_closest_canonical` itself).

Usage: slice_reference.py VOLAO_BINARY DATA_DIR   (run by tests/slices.rs)
"""

import os
import subprocess
import sys
import tempfile

import nibabel as nib
import numpy as np
import nrrd
from PIL import Image

WINDOW, LEVEL = 400.0, 100.0  # a fixed window the data straddles (greys, not all black/white)


def grey(values, window, level):
    lo = level - window / 2.0
    t = np.clip((values - lo) / window, 0.0, 1.0)
    g = np.floor(t * 255.0 + 0.5)
    return np.where(np.isnan(values), 0, g).astype(np.uint8)


def points_along(extent, step):
    return int(np.floor(extent / step + 1e-6)) + 1 if extent > 0 else 1


# World axis of the slice normal, and the (column, row) world axes.
AXES = {"axial": (2, (0, 1)), "coronal": (1, (0, 2)), "sagittal": (0, (1, 2))}


def reference_aligned(data, zooms, axis, index, neurological):
    """A slice of canonical (RAS-ordered) `data` with voxel sizes `zooms`."""
    normal, (u, v) = AXES[axis]
    plane = np.take(data, index, axis=normal)  # axes (u, v) in that order
    f = min(zooms[u], zooms[v])
    nu = points_along((data.shape[u] - 1) * zooms[u], f)
    nv = points_along((data.shape[v] - 1) * zooms[v], f)
    iu = np.minimum(np.floor(np.arange(nu) * f / zooms[u] + 0.5).astype(int), data.shape[u] - 1)
    iv = np.minimum(np.floor(np.arange(nv) * f / zooms[v] + 0.5).astype(int), data.shape[v] - 1)
    plane = plane[np.ix_(iu, iv)]  # (columns, rows), both growing towards R/A/S
    img = plane.T  # rows, columns
    img = img[::-1, :]  # anterior / superior at the top
    flip_columns = axis == "sagittal" or not neurological
    if flip_columns:
        img = img[:, ::-1]
    return img


def reference_oblique(data, affine, axis, index, neurological):
    """A slice of a volume with an oblique `affine`, resampled (nearest) onto the
    patient's axes at its finest spacing over the bounding box of its voxel centres."""
    lin, off = affine[:3, :3], affine[:3, 3]
    f = np.min(np.linalg.norm(lin, axis=0))
    last = np.array(data.shape[:3]) - 1
    corners = np.array([[i, j, k] for i in (0, last[0]) for j in (0, last[1]) for k in (0, last[2])])
    world = corners @ lin.T + off
    lo, hi = world.min(axis=0), world.max(axis=0)
    dims = [points_along(hi[i] - lo[i], f) for i in range(3)]
    normal, (u, v) = AXES[axis]
    cols = np.arange(dims[u])
    rows = np.arange(dims[v])
    p = np.zeros((len(rows), len(cols), 3))
    p[..., normal] = lo[normal] + index * f
    p[..., u] = lo[u] + cols[None, :] * f
    p[..., v] = lo[v] + rows[:, None] * f
    t = (p - off) @ np.linalg.inv(lin).T
    r = np.floor(t + 0.5)
    inside = np.all((r >= 0) & (r < np.array(data.shape[:3])), axis=-1)
    ri = np.where(inside[..., None], r, 0).astype(int)
    img = np.where(inside, data[ri[..., 0], ri[..., 1], ri[..., 2]], np.nan)
    img = img[::-1, :]
    if axis == "sagittal" or not neurological:
        img = img[:, ::-1]
    return img, dims


def canonical(img):
    c = nib.as_closest_canonical(img)
    return np.asarray(c.get_fdata(), dtype=np.float64), c.header.get_zooms()[:3]


def nrrd_image(path):
    data, h = nrrd.read(path)
    dirs = np.array(h["space directions"], dtype=float).T  # columns = voxel steps
    origin = np.array(h["space origin"], dtype=float)
    space = h.get("space", "")
    if space in ("left-posterior-superior", "LPS"):
        flip = np.diag([-1.0, -1.0, 1.0])
        dirs, origin = flip @ dirs, flip @ origin
    affine = np.eye(4)
    affine[:3, :3], affine[:3, 3] = dirs, origin
    return nib.Nifti1Image(data.astype(np.float64), affine)


def volao_slice(binary, source, axis, index, flags, out):
    cmd = [binary, "slice", source, "--axis", axis, "--index", str(index),
           "--window-level", f"{WINDOW},{LEVEL}", "-o", out] + flags
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return np.asarray(Image.open(out))


def main():
    binary, data = sys.argv[1], sys.argv[2]
    tmp = tempfile.mkdtemp(prefix="volao-slice-ref-")
    dcm = {}
    for series in ("cranium-ct", "brain-mr"):
        outdir = os.path.join(tmp, series)
        os.makedirs(outdir)
        subprocess.run(["dcm2niix", "-z", "n", "-f", "ref", "-o", outdir,
                        os.path.join(data, "dicom", series)], check=True, stdout=subprocess.DEVNULL)
        dcm[series] = nib.load(os.path.join(outdir, "ref.nii"))

    aligned = [
        ("NIfTI LAS", "nifti/avg152T1_LR_nifti.nii", nib.load(os.path.join(data, "nifti/avg152T1_LR_nifti.nii"))),
        ("NIfTI RAS", "nifti/ch2.nii.gz", nib.load(os.path.join(data, "nifti/ch2.nii.gz"))),
        ("NIfTI LAS anisotropic", "nifti/big.nii.gz", nib.load(os.path.join(data, "nifti/big.nii.gz"))),
        ("Analyze", "analyze/analyze75.hdr", nib.load(os.path.join(data, "analyze/analyze75.hdr"))),
        ("NRRD LPS", "nrrd/avg152.nhdr", nrrd_image(os.path.join(data, "nrrd/avg152.nhdr"))),
        ("NRRD LPS, negative x/y", "labels/slicer/CTChest4.nrrd",
         nrrd_image(os.path.join(data, "labels/slicer/CTChest4.nrrd"))),
        ("DICOM CT (dcm2niix)", "dicom/cranium-ct", dcm["cranium-ct"]),
        ("DICOM MR oblique, acquisition plane (dcm2niix)", "dicom/brain-mr", dcm["brain-mr"]),
    ]
    failures, checked = [], 0
    for name, rel, img in aligned:
        flags = ["--acquisition-plane"] if "acquisition" in name else []
        values, zooms = canonical(img)
        for axis, (normal, _) in AXES.items():
            n = values.shape[normal]
            for index, neuro in ((n // 2, False), (n // 3, True), (n - 1, False)):
                out = os.path.join(tmp, "s.png")
                got = volao_slice(binary, os.path.join(data, rel), axis, index,
                                  flags + (["--neurological"] if neuro else []), out)
                want = grey(reference_aligned(values, zooms, axis, index, neuro), WINDOW, LEVEL)
                checked += 1
                if got.shape != want.shape or not np.array_equal(got, want):
                    diff = "shape %s vs %s" % (got.shape, want.shape) if got.shape != want.shape \
                        else "%d pixels differ" % int(np.sum(got != want))
                    failures.append(f"{name} {axis} {index}{' neuro' if neuro else ''}: {diff}")

    # The oblique MR resampled onto the patient's axes.
    mr = dcm["brain-mr"]
    mr_data = np.asarray(mr.get_fdata(), dtype=np.float64)
    for axis, (normal, _) in AXES.items():
        for neuro in (False, True):
            _, dims = reference_oblique(mr_data, mr.affine, axis, 0, neuro)
            index = dims[normal] // 2
            want, _ = reference_oblique(mr_data, mr.affine, axis, index, neuro)
            out = os.path.join(tmp, "s.png")
            got = volao_slice(binary, os.path.join(data, "dicom/brain-mr"), axis, index,
                              ["--neurological"] if neuro else [], out)
            want = grey(want, WINDOW, LEVEL)
            checked += 1
            if got.shape != want.shape or not np.array_equal(got, want):
                diff = "shape %s vs %s" % (got.shape, want.shape) if got.shape != want.shape \
                    else "%d pixels differ" % int(np.sum(got != want))
                failures.append(f"DICOM MR oblique, patient axes {axis}{' neuro' if neuro else ''}: {diff}")

    for f in failures:
        print("MISMATCH", f)
    print(f"{checked - len(failures)} of {checked} slices equal to the reference")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
