"""Cohorts on Dask and Ray (examples/cohort_dask.py, examples/cohort_ray.py): scenes built
from ../shared/data rendered by two local worker processes, byte-identical to `volao
batch` of the same scenes; a scene pointing at a corrupt file is reported (after one
retry) while the others complete."""

from __future__ import annotations

import importlib.util
import json
import os
from pathlib import Path

import numpy as np
import pytest

import volao
from conftest import REPO, read_png, run_cli

# (name, file, settings): small volumes and images so lavapipe keeps the run short.
SCENES = [
    ("bucky", "pvm/Bucky.pvm", dict(ao="lao", rays=6, samples=4)),
    ("storm", "pvm/Storm-t11.pvm", dict(camera=(60.0, 20.0, 3.0))),
    ("storm_empty", "pvm/Storm-t01.pvm", {}),
    ("avg152", "nifti/avg152T1_LR_nifti.nii.gz", dict(tf="mr-t1-brain", ao="lao", rays=6, samples=4)),
    ("avg152_nrrd", "nrrd/avg152.nhdr", dict(mode="mip")),
    ("analyze", "analyze/analyze75.hdr", dict(camera=(90.0, 0.0, 3.0), shading="phong")),
    ("little", "nifti/little.nii.gz", dict(ao="cdf", window_level=(20.0, 5.0))),
    ("big_endian", "nifti/big.nii.gz", dict(camera=(200.0, 30.0, 3.0))),
    ("hydrogen", "raw/hydrogenatom.raw", dict(tf="ct-soft-tissue")),
]
CORRUPT = "z_corrupt"


@pytest.fixture(scope="module")
def scenes(data, tmp_path_factory) -> Path:
    """Nine scene files and one whose volume is not a NIfTI file."""
    folder = tmp_path_factory.mktemp("scenes")
    for name, file, settings in SCENES:
        volao.Scene(volao.load(data / file), width=48, height=40, **settings).save(folder / f"{name}.json")
    scene = json.loads((folder / "bucky.json").read_text())
    scene["volume"]["path"] = os.fspath(data / "nifti/not-nifti.nii")
    (folder / f"{CORRUPT}.json").write_text(json.dumps(scene))
    return folder


@pytest.fixture(scope="module")
def cli_images(scenes, volao_cli, tmp_path_factory) -> Path:
    """`volao batch` of the same scenes: the reference images."""
    out = tmp_path_factory.mktemp("cli")
    run = run_cli(volao_cli, "batch", scenes, "--out", out, ok=False)
    assert run.returncode == 1, "the corrupt scene fails the batch"
    assert f"failed: {scenes / (CORRUPT + '.json')}: " in run.stderr
    return out


def example(name: str):
    """An example script as a module (not registered, so Ray ships its task by value)."""
    spec = importlib.util.spec_from_file_location(name, REPO / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check_run(scenes: Path, out: Path, cli_images: Path, results, failures):
    names = sorted(n for n, _, _ in SCENES)
    assert sorted(Path(r["scene"]).stem for r in results) == names, "every good scene rendered"
    assert all(not r["skipped"] for r in results)
    assert len(failures) == 1, failures
    scene, reason = failures[0]
    assert Path(scene).stem == CORRUPT and "not-nifti.nii" in reason, failures
    for name in names:
        png, ref = out / f"{name}.png", cli_images / f"{name}.png"
        assert png.read_bytes() == ref.read_bytes(), f"{name}: the bytes of volao batch"
        assert np.array_equal(read_png(png), read_png(ref))
    # Each good scene ran once; the corrupt one once and its one retry.
    attempts = {p.name: len(p.read_text().splitlines()) for p in (out / ".attempts").iterdir()}
    assert attempts == {**{n: 1 for n in names}, CORRUPT: 2}, attempts
    assert not list(out.glob(".partial.*")), "no partial files"
    summary = volao.cohort.report(sorted(map(os.fspath, scenes.glob("*.json"))), results, failures, 1.0)
    assert "10 scenes: 9 rendered, 0 skipped (outputs exist), 1 failed" in summary
    assert summary.startswith(f"failed: {scene}: ")


def test_dask_local_cluster_renders_the_cohort(scenes, cli_images, tmp_path):
    from dask.distributed import Client, LocalCluster

    cohort = example("cohort_dask")
    files = volao.cohort.scene_files([scenes])
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster, Client(cluster) as client:
        results, failures = cohort.render_cohort(client, files, os.fspath(tmp_path))
        pids = {r["pid"] for r in client.run(lambda: {"pid": os.getpid()}).values()}
    assert len(pids) == 2, "two worker processes"
    check_run(scenes, tmp_path, cli_images, results, failures)
    # Run again: everything is there, nothing renders; the corrupt scene fails again.
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster, Client(cluster) as client:
        again, failed = cohort.render_cohort(client, files, os.fspath(tmp_path))
    assert all(r["skipped"] for r in again) and len(again) == 9 and len(failed) == 1


def test_ray_local_cluster_renders_the_cohort(scenes, cli_images, tmp_path):
    import ray

    cohort = example("cohort_ray")
    files = volao.cohort.scene_files([scenes])
    ray.init(num_cpus=2, include_dashboard=False)
    try:
        results, failures = cohort.render_cohort(files, os.fspath(tmp_path))
    finally:
        ray.shutdown()
    check_run(scenes, tmp_path, cli_images, results, failures)
