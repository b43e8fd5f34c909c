#!/usr/bin/env python3
"""Make a large benchmark volume from a small real one: the shared cranium CT (256x256x108
i16, Hounsfield units) upsampled trilinearly to 2048x2048x1024 u16 (8 GiB) by default,
written slab by slab (one output slice at a time), so it needs little memory whatever
the size.

Output: an uncompressed single-file NIfTI-1 (.nii, default) whose scl_inter = -1024 makes
the values Hounsfield units again (stored u16 = HU + 1024), or raw voxels + a detached
NRRD header (.nhdr), which has no rescale field (values are then HU + 1024). The physical
extent of the source is kept: the spacing shrinks as the dims grow.

Needs Python 3 and numpy only. Not run in CI: see README.md in this folder.
"""

import argparse
import os
import shutil
import struct
import sys

# The shared cranium CT (see ../shared/data/README.md): raw, no header.
CRANIUM = {
    "path": os.path.join("raw", "cranium-ct.raw"),
    "dims": (256, 256, 108),
    "dtype": "<i2",
    "spacing": (0.957031, 0.957031, 1.5),
}
OFFSET = 1024  # stored u16 = HU + OFFSET; HU -1024 (air) becomes 0


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="make-large.py",
        description=(
            "Upsample a raw CT (default: the shared cranium CT) trilinearly to a large "
            "u16 volume, slab by slab. Output folder: --out, else $VOLAO_DATA_OUT, else "
            "./data; files go into its large/ subfolder. An existing output is kept "
            "(use --force to rewrite)."
        ),
    )
    p.add_argument("--dims", nargs=3, type=int, metavar=("X", "Y", "Z"),
                   default=[2048, 2048, 1024],
                   help="output voxel counts (default 2048 2048 1024 = 8 GiB; "
                        "the other benchmark size is 1024 1024 600)")
    p.add_argument("--format", choices=["nii", "nhdr"], default="nii",
                   help="uncompressed NIfTI-1 with scl_inter = -1024 (default), or "
                        "raw + detached NRRD header (values HU + 1024)")
    p.add_argument("--src", help="source raw file (default: raw/cranium-ct.raw in "
                                 "$VOLAO_DATA or ../shared/data beside the repository)")
    p.add_argument("--src-dims", nargs=3, type=int, metavar=("X", "Y", "Z"),
                   help="source voxel counts (default: the cranium's 256 256 108)")
    p.add_argument("--src-spacing", nargs=3, type=float, metavar=("SX", "SY", "SZ"),
                   help="source spacing in mm (default: the cranium's)")
    p.add_argument("--min-free-gb", type=float, default=30.0,
                   help="refuse to write if less than this would stay free on the "
                        "output's disk (default 30)")
    p.add_argument("--out", help="output root folder")
    p.add_argument("--force", action="store_true", help="rewrite an existing output")
    args = p.parse_args(argv)
    if min(args.dims) < 2:
        p.error("--dims must be at least 2 on every axis")
    if args.format == "nii" and max(args.dims) > 32767:
        p.error("NIfTI-1 holds at most 32767 voxels per axis; use --format nhdr")
    return args


def default_source():
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    data = os.environ.get("VOLAO_DATA") or os.path.join(os.path.dirname(repo), "shared", "data")
    return os.path.join(data, CRANIUM["path"])


def axis_map(np, n_in, n_out):
    """For each output voxel centre, the two source voxels around it and the weight of the
    second (voxel centres aligned: the volumes cover the same extent)."""
    pos = (np.arange(n_out, dtype=np.float64) + 0.5) * (n_in / n_out) - 0.5
    pos = np.clip(pos, 0.0, n_in - 1.0)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, n_in - 1)
    return lo, hi, (pos - lo).astype(np.float32)


def slices(np, src, out_dims):
    """The output slices (z from 0), each a (Y, X) uint16 array, interpolated
    trilinearly from `src` (an (z, y, x) array; a memory map is fine)."""
    nz, ny, nx = src.shape
    ox, oy, oz = out_dims
    x0, x1, wx = axis_map(np, nx, ox)
    y0, y1, wy = axis_map(np, ny, oy)
    z0, z1, wz = axis_map(np, nz, oz)
    wy = wy[:, None]
    for k in range(oz):
        a = src[z0[k]].astype(np.float32)
        b = src[z1[k]].astype(np.float32)
        plane = a + wz[k] * (b - a)  # (ny, nx)
        rows = plane[y0] + wy * (plane[y1] - plane[y0])  # (oy, nx)
        out = rows[:, x0] + wx * (rows[:, x1] - rows[:, x0])  # (oy, ox)
        yield np.clip(np.rint(out) + OFFSET, 0, 65535).astype("<u2")


def nifti_header(dims, spacing, description):
    """348-byte NIfTI-1 header + empty extension flag, u16, scl_inter = -OFFSET, voxel
    axes RAS (the raw source has no orientation; volao assumes RAS for it too)."""
    nx, ny, nz = dims
    sx, sy, sz = spacing
    h = bytearray(348)
    struct.pack_into("<i", h, 0, 348)  # sizeof_hdr
    struct.pack_into("<8h", h, 40, 3, nx, ny, nz, 1, 1, 1, 1)  # dim
    struct.pack_into("<h", h, 70, 512)  # datatype: uint16
    struct.pack_into("<h", h, 72, 16)  # bitpix
    struct.pack_into("<8f", h, 76, 1.0, sx, sy, sz, 0, 0, 0, 0)  # pixdim
    struct.pack_into("<f", h, 108, 352.0)  # vox_offset
    struct.pack_into("<f", h, 112, 1.0)  # scl_slope
    struct.pack_into("<f", h, 116, -float(OFFSET))  # scl_inter: values are HU
    h[123] = 2  # xyzt_units: mm
    desc = description.encode("ascii", "replace")[:79]
    h[148:148 + len(desc)] = desc
    struct.pack_into("<h", h, 254, 1)  # sform_code: scanner
    struct.pack_into("<4f", h, 280, sx, 0, 0, 0)
    struct.pack_into("<4f", h, 296, 0, sy, 0, 0)
    struct.pack_into("<4f", h, 312, 0, 0, sz, 0)
    h[344:348] = b"n+1\0"
    return bytes(h) + b"\0\0\0\0"


def nhdr_text(raw_name, dims, spacing):
    sx, sy, sz = spacing
    return (
        "NRRD0004\n"
        "# volao datasets-scripts/make-large.py: stored = HU + 1024\n"
        "type: unsigned short\n"
        "dimension: 3\n"
        "space: right-anterior-superior\n"
        f"sizes: {dims[0]} {dims[1]} {dims[2]}\n"
        f"space directions: ({sx!r},0,0) (0,{sy!r},0) (0,0,{sz!r})\n"
        "space origin: (0,0,0)\n"
        "kinds: domain domain domain\n"
        "endian: little\n"
        "encoding: raw\n"
        f"data file: {raw_name}\n"
    )


def main(argv):
    args = parse_args(argv)
    try:
        import numpy as np
    except ImportError:
        print("make-large.py needs numpy: python3 -m pip install numpy", file=sys.stderr)
        return 1

    src_path = args.src or default_source()
    if not os.path.isfile(src_path):
        print(f"source not found: {src_path} (give --src, or set VOLAO_DATA)", file=sys.stderr)
        return 1
    src_dims = tuple(args.src_dims or CRANIUM["dims"])
    src_spacing = tuple(args.src_spacing or CRANIUM["spacing"])
    want_bytes = src_dims[0] * src_dims[1] * src_dims[2] * 2
    if os.path.getsize(src_path) != want_bytes:
        print(f"{src_path}: {os.path.getsize(src_path)} bytes, but {src_dims} i16 needs "
              f"{want_bytes}", file=sys.stderr)
        return 1
    src = np.memmap(src_path, dtype=CRANIUM["dtype"], mode="r",
                    shape=(src_dims[2], src_dims[1], src_dims[0]))

    dims = tuple(args.dims)
    spacing = tuple(src_spacing[i] * src_dims[i] / dims[i] for i in range(3))
    root = args.out or os.environ.get("VOLAO_DATA_OUT") or "./data"
    if not os.path.isdir(root):
        os.makedirs(root)
        with open(os.path.join(root, ".gitignore"), "w") as f:
            f.write("# generated data: never commit\n*\n")
    out_dir = os.path.join(root, "large")
    os.makedirs(out_dir, exist_ok=True)
    base = f"cranium-{dims[0]}x{dims[1]}x{dims[2]}-u16"
    voxel_bytes = dims[0] * dims[1] * dims[2] * 2
    if args.format == "nii":
        targets = [(os.path.join(out_dir, base + ".nii"), 352 + voxel_bytes)]
    else:
        targets = [(os.path.join(out_dir, base + ".raw"), voxel_bytes),
                   (os.path.join(out_dir, base + ".nhdr"), None)]
    if not args.force and all(os.path.isfile(p) and (n is None or os.path.getsize(p) == n)
                              for p, n in targets):
        print(f"skip  {targets[0][0]} (already there)")
        return 0
    free = shutil.disk_usage(out_dir).free
    if free - voxel_bytes < args.min_free_gb * 1e9:
        print(f"refusing: writing {voxel_bytes / 2**30:.2f} GiB would leave "
              f"{(free - voxel_bytes) / 1e9:.1f} GB free on {out_dir}, less than "
              f"--min-free-gb {args.min_free_gb:g}", file=sys.stderr)
        return 1

    data_path = targets[0][0]
    tmp = data_path + ".part"
    with open(tmp, "wb") as f:
        if args.format == "nii":
            f.write(nifti_header(dims, spacing, f"cranium CT upsampled to {base}"))
        for k, plane in enumerate(slices(np, src, dims)):
            f.write(plane.tobytes())
            if k % 64 == 0 or k == dims[2] - 1:
                print(f"\r{k + 1}/{dims[2]} slices", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    os.replace(tmp, data_path)
    if args.format == "nhdr":
        with open(targets[1][0], "w") as f:
            f.write(nhdr_text(os.path.basename(data_path), dims, spacing))
    print(f"wrote {', '.join(p for p, _ in targets)}: {dims[0]}x{dims[1]}x{dims[2]} u16, "
          f"spacing {spacing[0]:.6g} x {spacing[1]:.6g} x {spacing[2]:.6g} mm, "
          f"{voxel_bytes / 2**30:.2f} GiB of voxels")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
