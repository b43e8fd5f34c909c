#!/usr/bin/env python3
"""Convert an InVesalius 3 project (.inv3) into raw voxels + an Inviwo `.dat` sidecar.

An .inv3 file is a tar archive (usually gzip-compressed) of one folder holding
`main.plist` and the image matrix it names (normally `matrix.dat`): a headerless numpy
memmap in C order with shape (z, y, x), so x varies fastest, which is what a .raw needs.
`main.plist` gives the shape, the numpy dtype name (e.g. "int16") and the voxel spacing
in (x, y, z) order. InVesalius writes the memmap in the machine's byte order; the
projects it ships were made on little-endian PCs, so little-endian is assumed.

Writes OUT_DIR/NAME.raw and OUT_DIR/NAME.dat; `volao info OUT_DIR/NAME.raw` then works.
Masks and surfaces in the project are not converted. Python 3 standard library only.
"""

import argparse
import os
import plistlib
import shutil
import sys
import tarfile

# numpy dtype name -> (Inviwo Format, bytes per voxel)
FORMATS = {
    "int8": ("CHAR", 1),
    "uint8": ("UCHAR", 1),
    "int16": ("SHORT", 2),
    "uint16": ("USHORT", 2),
    "int32": ("INT", 4),
    "uint32": ("UINT", 4),
    "float32": ("FLOAT", 4),
    "float64": ("DOUBLE", 8),
}


def die(msg):
    sys.stderr.write(f"inv3-to-raw.py: {msg}\n")
    sys.exit(1)


def fmt_num(x):
    return "%.9g" % float(x)


def convert(inv3, out_dir, name, force=False):
    raw_path = os.path.join(out_dir, name + ".raw")
    dat_path = os.path.join(out_dir, name + ".dat")
    # The .dat is written only after the .raw is complete (renamed from .part), so both
    # being there means a finished earlier run.
    if not force and os.path.isfile(raw_path) and os.path.isfile(dat_path):
        print(f"skip  {raw_path} (already there; --force to redo)")
        return raw_path, dat_path
    try:
        tar = tarfile.open(inv3, "r:*")
    except (OSError, tarfile.TarError) as e:
        die(f"{inv3}: not a readable .inv3 (tar) archive: {e}")
    with tar:
        members = {m.name: m for m in tar.getmembers() if m.isfile()}
        plists = [n for n in members if os.path.basename(n) == "main.plist"]
        if len(plists) != 1:
            die(f"{inv3}: expected one main.plist in the archive, found {len(plists)}")
        folder = os.path.dirname(plists[0])
        project = plistlib.load(tar.extractfile(members[plists[0]]))
        try:
            matrix = project["matrix"]
            shape = [int(n) for n in matrix["shape"]]
            dtype = str(matrix["dtype"])
            fname = os.path.basename(str(matrix["filename"]))
            spacing = [float(s) for s in project["spacing"]]
        except (KeyError, TypeError, ValueError) as e:
            die(f"{inv3}: main.plist lacks a usable matrix/spacing entry ({e!r})")
        if len(shape) != 3 or len(spacing) != 3:
            die(f"{inv3}: expected a 3-D matrix and 3 spacings, got shape {shape}, spacing {spacing}")
        if dtype not in FORMATS:
            die(f"{inv3}: matrix dtype {dtype!r} has no .dat Format (known: {', '.join(FORMATS)})")
        fmt, size = FORMATS[dtype]
        nz, ny, nx = shape  # numpy shape is (z, y, x)
        sx, sy, sz = spacing  # InVesalius spacing is (x, y, z)
        expected = nx * ny * nz * size
        member = members.get(f"{folder}/{fname}" if folder else fname)
        if member is None:
            die(f"{inv3}: the archive has no {fname} beside main.plist")
        if member.size != expected:
            die(
                f"{inv3}: {fname} has {member.size} bytes but shape {shape} of {dtype} "
                f"needs {expected}"
            )
        text = (
            f"ObjectFileName: {name}.raw\n"
            f"Resolution: {nx} {ny} {nz}\n"
            f"SliceThickness: {fmt_num(sx)} {fmt_num(sy)} {fmt_num(sz)}\n"
            f"Format: {fmt}\n"
            f"ByteOrder: LittleEndian\n"
        )
        os.makedirs(out_dir, exist_ok=True)
        tmp = raw_path + ".part"
        with tar.extractfile(member) as src, open(tmp, "wb") as dst:
            shutil.copyfileobj(src, dst, 1 << 20)
        os.replace(tmp, raw_path)
        with open(dat_path, "w") as f:
            f.write(text)
    extra = ", ".join(
        f"{k} {project[k]}"
        for k in ("name", "modality", "scalar_range", "window_width", "window_level")
        if k in project
    )
    print(
        f"wrote {raw_path} + {os.path.basename(dat_path)}: {nx}x{ny}x{nz} {dtype} ({fmt}), "
        f"spacing {fmt_num(sx)} x {fmt_num(sy)} x {fmt_num(sz)}; {extra}"
    )
    return raw_path, dat_path


def main(argv):
    p = argparse.ArgumentParser(
        prog="inv3-to-raw.py",
        description=(
            "Extract the image volume of an InVesalius 3 project (.inv3) as NAME.raw plus "
            "an Inviwo NAME.dat sidecar (Resolution X Y Z, SliceThickness, Format) that "
            "volao reads. Existing output is kept unless --force."
        ),
    )
    p.add_argument("inv3", help="the .inv3 project file")
    p.add_argument("out_dir", nargs="?", default=".", help="output folder (default: .)")
    p.add_argument("--name", help="output base name (default: the .inv3 file's stem)")
    p.add_argument("--force", action="store_true", help="rewrite existing output")
    a = p.parse_args(argv)
    name = a.name or os.path.splitext(os.path.basename(a.inv3))[0]
    convert(a.inv3, a.out_dir, name, a.force)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
