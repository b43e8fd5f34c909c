#!/usr/bin/env python3
"""Loads one volume with Python (nibabel for NIfTI, numpy.fromfile for raw, pynrrd for
NRRD, pydicom + numpy for a DICOM folder) and prints the load time and peak memory as
JSON, for `volao bench load` to compare against. With --dcm2niix, times dcm2niix
converting the DICOM folder to NIfTI instead (peak memory of the child process).

Requires: pip install nibabel numpy pynrrd pydicom; apt-get install dcm2niix
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
    p.add_argument("--dcm2niix", action="store_true", help="time dcm2niix on a folder")
    a = p.parse_args()

    import os
    import numpy as np
    import nibabel as nib

    if a.dcm2niix:
        return run_dcm2niix(a.file, np, nib)
    before = status_kb("VmRSS")
    t0 = time.perf_counter()
    if os.path.isdir(a.file):
        import pydicom
        files = [os.path.join(a.file, f) for f in sorted(os.listdir(a.file))]
        slices = [pydicom.dcmread(f) for f in files]
        # Order along the slice normal, as volao does.
        iop = np.array(slices[0].ImageOrientationPatient, dtype=float)
        normal = np.cross(iop[:3], iop[3:])
        slices.sort(key=lambda d: float(np.dot(normal, np.array(d.ImagePositionPatient, dtype=float))))
        first = slices[0]
        data = np.empty((len(slices), first.Rows, first.Columns), dtype=first.pixel_array.dtype)
        for k, d in enumerate(slices):
            data[k] = d.pixel_array
        slope = float(getattr(first, "RescaleSlope", 1) or 1)
        inter = float(getattr(first, "RescaleIntercept", 0) or 0)
        reader = "pydicom " + pydicom.__version__ + " + numpy"
    elif a.file.endswith((".nrrd", ".nhdr")):
        import nrrd
        data, _ = nrrd.read(a.file)
        reader = "pynrrd " + nrrd.__version__
    elif a.raw_dtype:
        x, y, z = a.dims
        data = np.fromfile(a.file, dtype=a.raw_dtype).reshape((z, y, x))
        reader = "numpy.fromfile"
    else:
        img = nib.load(a.file)
        # dataobj keeps the stored dtype (get_fdata would widen to float64).
        data = np.asanyarray(img.dataobj)
        reader = "nibabel " + nib.__version__
    seconds = time.perf_counter() - t0
    # Peak memory of the load itself, before the checksum's float64 copy.
    hwm_kb = status_kb("VmHWM")
    checksum = float(data.astype(np.float64).mean())
    if os.path.isdir(a.file):
        checksum = checksum * slope + inter  # Hounsfield units, as volao reports
    print(json.dumps({
        "reader": reader,
        "seconds": seconds,
        "payload_bytes": int(data.nbytes),
        "rss_before_kb": before,
        "hwm_kb": hwm_kb,
        "checksum": checksum,
    }))


def run_dcm2niix(folder, np, nib):
    import resource
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        subprocess.run(
            ["dcm2niix", "-z", "n", "-b", "n", "-f", "bench", "-o", out, folder],
            check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        seconds = time.perf_counter() - t0
        hwm_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        img = nib.load(out + "/bench.nii")
        raw = img.dataobj.get_unscaled()
        checksum = float(np.asarray(img.get_fdata(dtype=np.float64)).mean())
        version = subprocess.run(["dcm2niix", "-v"], capture_output=True, text=True).stdout
    print(json.dumps({
        "reader": "dcm2niix " + (version.split()[-1] if version.split() else "") + " (convert to .nii)",
        "seconds": seconds,
        "payload_bytes": int(raw.nbytes),
        "rss_before_kb": 0,
        "hwm_kb": hwm_kb,
        "checksum": checksum,
    }))


if __name__ == "__main__":
    sys.exit(main())
