#!/usr/bin/env python3
"""Loads one volume with Python (nibabel for NIfTI, numpy.fromfile for raw) and prints
the load time and peak memory as JSON, for `volao bench load` to compare against.

Requires: pip install nibabel numpy
"""
import json
import sys
import time


def status_kb(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def main():
    import argparse

    p = argparse.ArgumentParser()
    p.add_argument("file")
    p.add_argument("--raw-dtype", help="numpy dtype of a raw file, e.g. <i2")
    p.add_argument("--dims", nargs=3, type=int, help="raw: x y z")
    a = p.parse_args()

    import numpy as np
    import nibabel as nib

    before = status_kb("VmRSS")
    t0 = time.perf_counter()
    if a.raw_dtype:
        x, y, z = a.dims
        data = np.fromfile(a.file, dtype=a.raw_dtype).reshape((z, y, x))
        reader = "numpy.fromfile"
    else:
        img = nib.load(a.file)
        # dataobj keeps the stored dtype (get_fdata would widen to float64).
        data = np.asanyarray(img.dataobj)
        reader = "nibabel " + nib.__version__
    seconds = time.perf_counter() - t0
    print(json.dumps({
        "reader": reader,
        "seconds": seconds,
        "payload_bytes": int(data.nbytes),
        "rss_before_kb": before,
        "hwm_kb": status_kb("VmHWM"),
        "checksum": float(data.astype(np.float64).mean()),
    }))


if __name__ == "__main__":
    sys.exit(main())
