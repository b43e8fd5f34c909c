#!/usr/bin/env python3
"""volao's ray caster beside VTK's vtkOpenGLGPUVolumeRayCastMapper, same machine, same
volume, transfer function, camera and sample distance; and the figures of docs/looks.md.

Run from the repository root after `cargo build --release`, under a virtual X server
(VTK renders through OpenGL; on a machine without a GPU that is Mesa's llvmpipe):

    xvfb-run -a python3 benches/vtk_compare.py                   # timing table
    xvfb-run -a python3 benches/vtk_compare.py --sizes 512 --runs 3 \\
        --volao target/release/volao --volao /tmp/volao-before   # several binaries
    xvfb-run -a python3 benches/vtk_compare.py --looks docs/images   # the figures

The first run installs `vtk` and `numpy` from PyPI into benches/.venv and restarts in it.

What is the same on both sides: the cranium CT (raw/cranium-ct.raw, 256×256×108 i16,
0.957 × 0.957 × 1.5 mm, voxel indices taken as RAS as volao does for a raw file), the
ct-bone preset read point for point from src/tf/presets.json (opacity per voxel of the
smallest spacing: VTK's scalar opacity unit distance), camera azimuth 30°, elevation
20°, 3.2 bounding-sphere radii from the volume's centre, 30° vertical field of view,
z up (src/render/camera.rs), sample distance 0.5 voxel of the smallest spacing,
jittered ray starts, black background, Phong with ambient 0.4, diffuse 0.6, specular
0.3, shininess 24 and a headlight. Times are warm frames (after two unmeasured ones),
image readback to the host included on both sides; the median is reported.
"""
import argparse
import json
import math
import os
import plistlib
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
VENV = os.path.join(HERE, ".venv")


def ensure_vtk():
    """Imports vtk and numpy, installing them into benches/.venv on first use."""
    try:
        import numpy  # noqa: F401
        import vtk  # noqa: F401
        return
    except ImportError:
        pass
    python = os.path.join(VENV, "bin", "python")
    if os.path.abspath(sys.executable) == os.path.abspath(python):
        sys.exit("vtk is not importable even in benches/.venv: pip install vtk numpy there")
    if not os.path.exists(python):
        print("installing vtk and numpy into benches/.venv …", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", VENV], check=True)
        subprocess.run([python, "-m", "pip", "install", "-q", "vtk", "numpy"], check=True)
    os.execv(python, [python, os.path.abspath(__file__)] + sys.argv[1:])


# ---------------------------------------------------------------- volumes and TFs


def load_cranium(data):
    """raw/cranium-ct.raw with its InVesalius .plist: (z, y, x) int16 array, spacing."""
    import numpy as np

    raw = os.path.join(data, "raw", "cranium-ct.raw")
    with open(os.path.join(data, "raw", "cranium-ct.plist"), "rb") as f:
        meta = plistlib.load(f)
    shape = tuple(meta["matrix"]["shape"])  # (z, y, x)
    spacing = [float(s) for s in meta["spacing"]]
    voxels = np.fromfile(raw, dtype="<i2").reshape(shape)
    return voxels, spacing, raw


def load_via_volao(volao, path):
    """Any volume volao reads, converted by `volao convert` to raw + .dat first."""
    import numpy as np

    tmp = tempfile.mkdtemp(prefix="vtk_compare_")
    out = os.path.join(tmp, "volume.raw")
    subprocess.run([volao, "convert", path, out], check=True, capture_output=True)
    fields = {}
    with open(os.path.join(tmp, "volume.dat")) as f:
        for line in f:
            if ":" in line:
                k, v = line.split(":", 1)
                fields[k.strip()] = v.strip()
    dims = [int(x) for x in fields["Resolution"].split()]
    spacing = [float(x) for x in fields["SliceThickness"].split()]
    dtype = {"UCHAR": "u1", "USHORT": "u2", "SHORT": "i2", "FLOAT": "f4"}[fields["Format"]]
    order = "<" if fields.get("ByteOrder", "LittleEndian") == "LittleEndian" else ">"
    voxels = np.fromfile(out, dtype=order + dtype).reshape(dims[::-1])
    return voxels, spacing


def preset(name, lo, hi):
    """A preset of src/tf/presets.json in data units (relative ones over [lo, hi])."""
    with open(os.path.join(ROOT, "src", "tf", "presets.json")) as f:
        p = next(p for p in json.load(f) if p["name"] == name)
    place = (lambda x: x) if p["units"] == "absolute" else (lambda x: lo + (hi - lo) * x)
    return [(place(v), a) for v, a in p["opacity"]], [(place(v), c) for v, c in p["color"]]


# ---------------------------------------------------------------- VTK


class VtkScene:
    """One volume in an offscreen VTK window, posed like volao's camera."""

    def __init__(self, voxels, spacing, tf, size):
        import vtk
        from vtk.util import numpy_support

        nz, ny, nx = voxels.shape
        extent = [nx * spacing[0], ny * spacing[1], nz * spacing[2]]
        image = vtk.vtkImageData()
        image.SetDimensions(nx, ny, nz)
        image.SetSpacing(spacing)
        # Voxel centres where volao puts them: the box [-extent/2, extent/2].
        image.SetOrigin([-e / 2 + s / 2 for e, s in zip(extent, spacing)])
        image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(voxels.ravel(), deep=True))
        self.min_spacing = min(spacing)
        self.radius = 0.5 * math.sqrt(sum(e * e for e in extent))

        opacity, color = tf
        otf = vtk.vtkPiecewiseFunction()
        for v, a in opacity:
            otf.AddPoint(v, a)
        ctf = vtk.vtkColorTransferFunction()
        for v, (r, g, b) in color:
            ctf.AddRGBPoint(v, r, g, b)
        prop = vtk.vtkVolumeProperty()
        prop.SetScalarOpacity(otf)
        prop.SetColor(ctf)
        prop.SetInterpolationTypeToLinear()
        prop.SetScalarOpacityUnitDistance(self.min_spacing)
        prop.SetAmbient(0.4)
        prop.SetDiffuse(0.6)
        prop.SetSpecular(0.3)
        prop.SetSpecularPower(24.0)
        mapper = vtk.vtkOpenGLGPUVolumeRayCastMapper()
        mapper.SetInputData(image)
        mapper.SetBlendModeToComposite()
        mapper.SetAutoAdjustSampleDistances(False)
        mapper.SetSampleDistance(0.5 * self.min_spacing)
        mapper.SetUseJittering(True)
        volume = vtk.vtkVolume()
        volume.SetMapper(mapper)
        volume.SetProperty(prop)

        renderer = vtk.vtkRenderer()
        renderer.SetBackground(0, 0, 0)
        renderer.AddVolume(volume)
        window = vtk.vtkRenderWindow()
        window.SetOffScreenRendering(True)
        window.SetMultiSamples(0)
        window.SetSize(size, size)
        window.AddRenderer(renderer)
        self.vtk, self.window, self.renderer = vtk, window, renderer
        self.mapper, self.prop = mapper, prop
        self.pose(30.0, 20.0, 3.2)

    def pose(self, azimuth, elevation, distance):
        az, el = math.radians(azimuth), math.radians(elevation)
        back = (math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el))
        cam = self.renderer.GetActiveCamera()
        cam.SetFocalPoint(0, 0, 0)
        cam.SetPosition(*[b * distance * self.radius for b in back])
        cam.SetViewUp(0, 0, 1)
        cam.SetViewAngle(30.0)
        self.renderer.ResetCameraClippingRange()

    def shade(self, on, scattering=None, intensity=1.0):
        """Phong (or no shading), optionally VTK's volumetric scattering (blending 0–2,
        global-illumination reach 0–1) with the headlight at `intensity`."""
        self.prop.SetShade(1 if on else 0)
        if scattering is not None:
            blending, reach = scattering
            self.mapper.SetVolumetricScatteringBlending(blending)
            self.mapper.SetGlobalIlluminationReach(reach)
        if self.renderer.GetLights().GetNumberOfItems() == 0:
            self.frame()  # the renderer makes its headlight on the first frame
        lights = self.renderer.GetLights()
        lights.InitTraversal()
        lights.GetNextItem().SetIntensity(intensity)

    def frame(self):
        """Renders and reads the image back (as `volao bench render` does)."""
        self.window.Render()
        w, h = self.window.GetSize()
        return self.window.GetRGBACharPixelData(0, 0, w - 1, h - 1, 0)

    def time(self, runs):
        self.frame()
        self.frame()
        times = []
        for _ in range(runs):
            start = time.perf_counter()
            self.frame()
            times.append(time.perf_counter() - start)
        return statistics.median(times)

    def renderer_string(self):
        """The OpenGL renderer (known once a frame has been drawn)."""
        caps = self.window.ReportCapabilities()
        for line in caps.splitlines():
            if "renderer string" in line:
                return line.split(":", 1)[1].strip()
        return "unknown"

    def save(self, path):
        self.frame()
        grab = self.vtk.vtkWindowToImageFilter()
        grab.SetInput(self.window)
        grab.ReadFrontBufferOff()
        grab.Update()
        writer = self.vtk.vtkPNGWriter()
        writer.SetFileName(path)
        writer.SetInputConnection(grab.GetOutputPort())
        writer.Write()


# ---------------------------------------------------------------- timing


def volao_times(volao, raw, size, runs):
    """`volao bench render … --json`: {(mode, shading): ms} and the adapter."""
    cmd = [volao, "bench", "render", raw, "--tf", "ct-bone", "--width", str(size),
           "--height", str(size), "--runs", str(runs), "--mode", "composite,mip",
           "--shading", "none,phong", "--json"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    return {(r["mode"], r["shading"]): r["median_frame_ms"] for r in rows}, rows[0]["adapter"]


def timing(args):
    voxels, spacing, raw = load_cranium(args.data)
    tf = preset("ct-bone", float(voxels.min()), float(voxels.max()))
    print(f"load average before: {os.getloadavg()[0]:.2f}", file=sys.stderr)
    results = []
    for size in args.sizes:
        scene = VtkScene(voxels, spacing, tf, size)
        vtk_ms = {}
        for shaded in (False, True):
            scene.shade(shaded)
            vtk_ms[shaded] = scene.time(args.runs) * 1e3
        # VTK's own maximum intensity projection, unshaded, beside its compositing.
        scene.shade(False)
        scene.mapper.SetBlendModeToMaximumIntensity()
        vtk_ms["mip"] = scene.time(args.runs) * 1e3
        scene.mapper.SetBlendModeToComposite()
        renderer = scene.renderer_string()
        del scene
        for volao in args.volao:
            ms, adapter = volao_times(volao, raw, size, args.runs)
            results.append((size, volao, adapter, ms, renderer, vtk_ms))
            print(json.dumps({"size": size, "volao": volao, "adapter": adapter,
                              "volao_ms": {f"{m}/{s}": v for (m, s), v in ms.items()},
                              "vtk_renderer": renderer, "vtk_unshaded_ms": vtk_ms[False],
                              "vtk_shaded_ms": vtk_ms[True], "vtk_mip_ms": vtk_ms["mip"]}),
                  flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}", file=sys.stderr)
    print()
    print("| size | binary | volao unshaded | volao Phong | Phong / unshaded | volao MIP "
          "| MIP / composite | VTK unshaded | VTK shaded | VTK MIP | VTK MIP / composite "
          "| volao / VTK unshaded |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for size, volao, _, ms, _, vtk_ms in results:
        none, phong, mip = ms[("composite", "none")], ms[("composite", "phong")], ms[("mip", "none")]
        print(f"| {size}² | {volao} | {none:.0f} ms | {phong:.0f} ms | {phong / none:.2f} "
              f"| {mip:.0f} ms | {mip / none:.2f} | {vtk_ms[False]:.0f} ms "
              f"| {vtk_ms[True]:.0f} ms | {vtk_ms['mip']:.0f} ms "
              f"| {vtk_ms['mip'] / vtk_ms[False]:.2f} | {none / vtk_ms[False]:.2f} |")
    print()
    print(f"volao adapter: {results[0][2]}; VTK {__import__('vtk').vtkVersion.GetVTKVersion()} "
          f"OpenGL renderer: {results[0][4]}")


# ---------------------------------------------------------------- figures

# (name, volume path under --data, preset, camera (azimuth, elevation, distance), the
# clip shape volao carves with CAO). The Lobster is flat (56 slices): seen from higher
# and closer.
LOOK_VOLUMES = [
    ("cranium", "raw/cranium-ct.raw", "ct-bone", (30, 20, 3.2), "sphere:45,40,35,55"),
    ("lobster", "pvm/Lobster.pvm", "cao-single-color", (30, 40, 2.4), "plane:0,0,5,0,0,1"),
]


def looks(args):
    os.makedirs(args.looks, exist_ok=True)
    volao = args.volao[0]
    size = str(args.look_size)
    for name, rel, tf_name, camera, carve in LOOK_VOLUMES:
        path = os.path.join(args.data, rel)
        base = [volao, "render", path, "--tf", tf_name, "--width", size, "--height", size,
                "--camera", ",".join(str(c) for c in camera)]
        volao_looks = {
            "volao_phong": [],
            "volao_lao26": ["--ao", "lao", "--rays", "26"],
            "volao_lao26_shadows": ["--ao", "lao", "--rays", "26", "--shadows"],
            "volao_cao26_carved": ["--ao", "cao", "--rays", "26", "--clip", carve],
        }
        for look, extra in volao_looks.items():
            out = os.path.join(args.looks, f"{name}_{look}.png")
            print(f"{out}: volao render {' '.join(extra)}", file=sys.stderr)
            subprocess.run(base + extra + ["-o", out], check=True, capture_output=True)
        if rel.endswith(".raw"):
            voxels, spacing, _ = load_cranium(args.data)
        else:
            voxels, spacing = load_via_volao(volao, path)
        tf = preset(tf_name, float(voxels.min()), float(voxels.max()))
        scene = VtkScene(voxels, spacing, tf, args.look_size)
        scene.pose(*camera)
        scene.shade(True)
        scene.save(os.path.join(args.looks, f"{name}_vtk_phong.png"))
        blending, reach, intensity = args.scattering
        scene.shade(True, (blending, reach), intensity)
        scene.save(os.path.join(args.looks, f"{name}_vtk_scattering.png"))
        print(f"{name}: VTK Phong and scattering (blending {blending}, reach {reach}, "
              f"light {intensity})", file=sys.stderr)


def main():
    ensure_vtk()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    p.add_argument("--volao", action="append",
                   help="volao binary (repeatable; default target/release/volao)")
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--sizes", default="512,1024")
    p.add_argument("--looks", help="write the figures into this folder instead of timing")
    p.add_argument("--look-size", type=int, default=512)
    p.add_argument("--scattering", type=float, nargs=3, default=(1.0, 0.3, 2.0),
                   metavar=("BLENDING", "REACH", "LIGHT"),
                   help="VTK's volumetric scattering blending (0–2), global-illumination "
                   "reach (0–1) and headlight intensity (scattering alone is dim at 1)")
    args = p.parse_args()
    args.volao = args.volao or [os.path.join(ROOT, "target", "release", "volao")]
    args.sizes = [int(s) for s in args.sizes.split(",")]
    if args.looks:
        looks(args)
    else:
        timing(args)


if __name__ == "__main__":
    main()
