#!/usr/bin/env python3
"""Generate synthetic test volumes for volao as raw voxels + Inviwo `.dat` sidecars.

Each volume NAME is written as NAME-<size>-<type>.raw (little-endian voxels, x fastest,
then y, then z) and NAME-<size>-<type>.dat, which volao reads with `volao info FILE.raw`
or `volao info FILE.dat`. With --nifti a single-file NIfTI-1 (.nii) is written as well.

Needs Python 3 and numpy only.
"""

import argparse
import math
import os
import struct
import sys

VOLUMES = {
    "sphere": "solid ball, radius 0.8 of the half-width, one-voxel anti-aliased edge",
    "shells": "three nested spherical shells (radii 0.3/0.55/0.8) at values 1/3, 2/3 and 1",
    "marschner-lobb": "Marschner-Lobb test signal (fM = 6, alpha = 0.25); classic size 41",
    "torus": "solid torus around the z axis (major radius 0.55, minor radius 0.2)",
    "step": "step edge: 0 for x < 0, full value for x >= 0 (a plane at mid-x)",
    "ramp": "linear ramp along x from 0 to full value",
    "voxel": "all zeros except one full-value voxel at the centre (n//2, n//2, n//2)",
    "zeros": "all zeros",
}
DEFAULT_SIZE = 64
ML_CLASSIC_SIZE = 41

# type name -> (numpy dtype, Inviwo Format, NIfTI datatype code, bits, full-scale value)
TYPES = {
    "u8": ("<u1", "UCHAR", 2, 8, 255.0),
    "u16": ("<u2", "USHORT", 512, 16, 65535.0),
    "f32": ("<f4", "FLOAT", 16, 32, 1.0),
}


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="make-synthetic.py",
        description=(
            "Generate synthetic test volumes as .raw + Inviwo .dat sidecars "
            "(optionally also .nii). Output folder: --out, else $VOLAO_DATA_OUT, "
            "else ./data; files go into its synthetic/ subfolder. Existing files are "
            "kept (use --force to rewrite)."
        ),
        epilog="volumes:\n"
        + "\n".join(f"  {k:15s} {v}" for k, v in VOLUMES.items())
        + "\n\nvalues: u8 volumes span 0..255, u16 0..65535, f32 0..1 "
        "(the same shape function, scaled).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "volumes",
        nargs="*",
        metavar="VOLUME",
        help="which volumes to make (default: all). One of: " + ", ".join(VOLUMES),
    )
    p.add_argument(
        "--out",
        default=None,
        help="output root (default: $VOLAO_DATA_OUT or ./data); files go to OUT/synthetic/",
    )
    p.add_argument(
        "--size",
        type=int,
        default=None,
        help=f"edge length N of the N×N×N grid (default {DEFAULT_SIZE}; "
        f"{ML_CLASSIC_SIZE} for marschner-lobb)",
    )
    p.add_argument(
        "--dims",
        type=int,
        nargs=3,
        metavar=("X", "Y", "Z"),
        default=None,
        help="non-cubic grid X×Y×Z (overrides --size)",
    )
    p.add_argument(
        "--type",
        dest="types",
        action="append",
        choices=sorted(TYPES),
        help="voxel type; repeat for several (default: u8)",
    )
    p.add_argument(
        "--spacing",
        type=float,
        nargs=3,
        metavar=("SX", "SY", "SZ"),
        default=(1.0, 1.0, 1.0),
        help="voxel spacing written to the sidecar (default 1 1 1)",
    )
    p.add_argument("--nifti", action="store_true", help="also write NAME-...nii (NIfTI-1)")
    p.add_argument("--force", action="store_true", help="rewrite files that already exist")
    p.add_argument("--list", action="store_true", help="list the volumes and exit")
    args = p.parse_args(argv)
    unknown = [v for v in args.volumes if v not in VOLUMES]
    if unknown:
        p.error(f"unknown volume(s): {', '.join(unknown)} (choose from {', '.join(VOLUMES)})")
    for d in args.dims or []:
        if d < 1:
            p.error("--dims must be positive")
    if args.size is not None and args.size < 1:
        p.error("--size must be positive")
    if any(not (s > 0 and math.isfinite(s)) for s in args.spacing):
        p.error("--spacing must be positive")
    return args


def import_numpy():
    try:
        import numpy  # noqa: F401
    except ImportError:
        sys.stderr.write(
            "make-synthetic.py: numpy is not installed for this Python "
            f"({sys.executable}).\n"
            "Install it with one of:\n"
            "  python3 -m pip install --user numpy\n"
            "  sudo apt-get install python3-numpy      (Debian/Ubuntu)\n"
        )
        sys.exit(2)
    return numpy


def coords(np, dims):
    """Sample positions in [-1, 1] along each axis, endpoints included, as a broadcastable
    (z, y, x) grid: voxel i of n sits at -1 + 2 i / (n - 1) (0 for n == 1)."""

    def axis(n):
        if n == 1:
            return np.zeros(1)
        return np.linspace(-1.0, 1.0, n)

    nx, ny, nz = dims
    x = axis(nx)[None, None, :]
    y = axis(ny)[None, :, None]
    z = axis(nz)[:, None, None]
    return x, y, z


def smooth_inside(np, signed_dist, dims):
    """1 inside, 0 outside, linear across one voxel around signed_dist == 0
    (signed_dist < 0 inside, in the [-1, 1] units of coords())."""
    h = 2.0 / max(max(dims) - 1, 1)  # one voxel in coordinate units
    return np.clip(0.5 - signed_dist / h, 0.0, 1.0)


def marschner_lobb(np, x, y, z, f_m=6.0, alpha=0.25):
    """Marschner & Lobb (1994), "An evaluation of reconstruction filters for volume
    rendering", eq. for the test signal on [-1, 1]^3:
        rho(x,y,z) = (1 - sin(pi z / 2) + alpha (1 + rho_r(sqrt(x^2 + y^2)))) / (2 (1 + alpha))
        rho_r(r)   = cos(2 pi f_M cos(pi r / 2))
    Its range is [0, 1]."""
    r = np.sqrt(x * x + y * y)
    rho_r = np.cos(2.0 * math.pi * f_m * np.cos(math.pi * r / 2.0))
    return (1.0 - np.sin(math.pi * z / 2.0) + alpha * (1.0 + rho_r)) / (2.0 * (1.0 + alpha))


def shape(np, name, dims):
    """The volume as float64 in [0, 1], shape (nz, ny, nx)."""
    nx, ny, nz = dims
    x, y, z = coords(np, dims)
    full = (nz, ny, nx)
    if name == "zeros":
        return np.zeros(full)
    if name == "voxel":
        v = np.zeros(full)
        v[nz // 2, ny // 2, nx // 2] = 1.0
        return v
    if name == "step":
        return np.broadcast_to((np.arange(nx) >= nx // 2).astype(np.float64)[None, None, :], full).copy()
    if name == "ramp":
        return np.broadcast_to((x + 1.0) / 2.0, full).copy()
    if name == "marschner-lobb":
        return np.broadcast_to(marschner_lobb(np, x, y, z), full).copy()
    r = np.sqrt(x * x + y * y + z * z)
    if name == "sphere":
        return np.broadcast_to(smooth_inside(np, r - 0.8, dims), full).copy()
    if name == "shells":
        v = np.zeros(full)
        half = 0.06  # half thickness of each shell
        for radius, value in ((0.3, 1.0 / 3.0), (0.55, 2.0 / 3.0), (0.8, 1.0)):
            inside = smooth_inside(np, np.abs(r - radius) - half, dims)
            v = np.maximum(v, value * inside)
        return v
    if name == "torus":
        major, minor = 0.55, 0.2
        q = np.sqrt(x * x + y * y) - major
        d = np.sqrt(q * q + z * z) - minor
        return np.broadcast_to(smooth_inside(np, d, dims), full).copy()
    raise ValueError(name)


def quantise(np, v, ty):
    dtype, _, _, _, full = TYPES[ty]
    if ty == "f32":
        return v.astype(dtype)
    return np.rint(np.clip(v, 0.0, 1.0) * full).astype(dtype)


def fmt_num(x):
    return ("%.9g" % x)


def dat_text(raw_name, dims, spacing, ty):
    return (
        f"ObjectFileName: {raw_name}\n"
        f"Resolution: {dims[0]} {dims[1]} {dims[2]}\n"
        f"SliceThickness: {' '.join(fmt_num(s) for s in spacing)}\n"
        f"Format: {TYPES[ty][1]}\n"
        f"ByteOrder: LittleEndian\n"
    )


def nifti_header(dims, spacing, ty, description):
    """A 348-byte NIfTI-1 header + 4-byte (empty) extension flag; voxels follow at 352."""
    _, _, code, bits, _ = TYPES[ty]
    nx, ny, nz = dims
    sx, sy, sz = spacing
    h = bytearray(348)
    struct.pack_into("<i", h, 0, 348)  # sizeof_hdr
    struct.pack_into("<8h", h, 40, 3, nx, ny, nz, 1, 1, 1, 1)  # dim
    struct.pack_into("<h", h, 70, code)  # datatype
    struct.pack_into("<h", h, 72, bits)  # bitpix
    struct.pack_into("<8f", h, 76, 1.0, sx, sy, sz, 0, 0, 0, 0)  # pixdim (qfac = 1)
    struct.pack_into("<f", h, 108, 352.0)  # vox_offset
    struct.pack_into("<f", h, 112, 1.0)  # scl_slope
    struct.pack_into("<f", h, 116, 0.0)  # scl_inter
    h[123] = 2 | 8  # xyzt_units: mm, s
    desc = description.encode("ascii", "replace")[:79]
    h[148 : 148 + len(desc)] = desc  # descrip
    struct.pack_into("<h", h, 252, 0)  # qform_code
    struct.pack_into("<h", h, 254, 1)  # sform_code: scanner
    # sform: voxel (i, j, k) -> mm, centred on the volume
    ox, oy, oz = (-(nx - 1) * sx / 2, -(ny - 1) * sy / 2, -(nz - 1) * sz / 2)
    struct.pack_into("<4f", h, 280, sx, 0, 0, ox)
    struct.pack_into("<4f", h, 296, 0, sy, 0, oy)
    struct.pack_into("<4f", h, 312, 0, 0, sz, oz)
    h[344:348] = b"n+1\0"
    return bytes(h) + b"\0\0\0\0"


def write_atomically(path, chunks):
    tmp = path + ".part"
    with open(tmp, "wb") as f:
        for c in chunks:
            f.write(c)
    os.replace(tmp, path)


def main(argv):
    args = parse_args(argv)
    if args.list:
        for k, v in VOLUMES.items():
            print(f"{k:15s} {v}")
        return 0
    np = import_numpy()

    root = args.out or os.environ.get("VOLAO_DATA_OUT") or "./data"
    out = os.path.join(root, "synthetic")
    if not os.path.isdir(root):
        os.makedirs(root)
        # a folder this script creates keeps itself out of any git work tree it lands in
        with open(os.path.join(root, ".gitignore"), "w") as f:
            f.write("# generated data: never commit\n*\n")
    os.makedirs(out, exist_ok=True)
    names = args.volumes or list(VOLUMES)
    types = args.types or ["u8"]
    made = skipped = 0
    for name in names:
        if args.dims:
            dims = tuple(args.dims)
            tag = "x".join(str(d) for d in dims)
        else:
            n = args.size or (ML_CLASSIC_SIZE if name == "marschner-lobb" else DEFAULT_SIZE)
            dims = (n, n, n)
            tag = str(n)
        values = None
        for ty in types:
            base = f"{name}-{tag}-{ty}"
            raw_path = os.path.join(out, base + ".raw")
            dat_path = os.path.join(out, base + ".dat")
            nii_path = os.path.join(out, base + ".nii")
            voxel_bytes = dims[0] * dims[1] * dims[2] * np.dtype(TYPES[ty][0]).itemsize
            text = dat_text(base + ".raw", dims, args.spacing, ty)
            want = [(raw_path, voxel_bytes), (dat_path, len(text.encode()))]
            if args.nifti:
                want.append((nii_path, 352 + voxel_bytes))
            if not args.force and all(
                os.path.isfile(p) and os.path.getsize(p) == size for p, size in want
            ):
                print(f"skip  {base} (already there)")
                skipped += 1
                continue
            if values is None:
                values = shape(np, name, dims)
            data = np.ascontiguousarray(quantise(np, values, ty)).tobytes()
            assert len(data) == voxel_bytes
            write_atomically(raw_path, [data])
            write_atomically(dat_path, [text.encode()])
            files = [raw_path, dat_path]
            if args.nifti:
                hdr = nifti_header(dims, args.spacing, ty, f"volao synthetic {name}")
                write_atomically(nii_path, [hdr, data])
                files.append(nii_path)
            print(
                f"wrote {base}: {dims[0]}x{dims[1]}x{dims[2]} {ty}, "
                f"{voxel_bytes} voxel bytes -> " + ", ".join(files)
            )
            made += 1
    print(f"done: {made} written, {skipped} already present, in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
