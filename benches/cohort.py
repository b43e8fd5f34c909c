#!/usr/bin/env python3
"""Scenes per minute for a cohort: 16 views of the cranium CT at 512² with 14-ray LAO
(docs/images/cranium_lao.json turned round the head in 22.5° steps), rendered by
`volao batch` in one process and by Dask (examples/cohort_dask.py: a LocalCluster of
`--workers` single-threaded worker processes on this machine), each into a fresh folder.
Checks that both wrote the same bytes and prints a Markdown table for
docs/benchmarks.md, labelled with the adapter and the date.

    cargo build --release
    (cd python && maturin build --release -o ../target/wheels) && pip install --force-reinstall target/wheels/volao-*.whl
    python3 benches/cohort.py [--workers 2] [--scenes 16] [--size 512]

Requires the volao wheel, dask[distributed]; reads ../shared/data.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def make_scenes(folder: Path, count: int, size: int) -> list[str]:
    """`count` views of docs/images/cranium_lao.json with 14-ray LAO at size²."""
    base = json.loads((REPO / "docs/images/cranium_lao.json").read_text())
    volume = (REPO / "docs/images" / base["volume"]["path"]).resolve()
    if not volume.is_file():
        sys.exit(f"the cranium CT is missing: expected {volume} (../shared/data)")
    base["volume"]["path"] = os.fspath(volume)
    base["width"] = base["height"] = size
    base["ambient_occlusion"].update(method="lao", rays="14")
    files = []
    for i in range(count):
        scene = json.loads(json.dumps(base))
        scene["camera"]["azimuth_deg"] = i * 360.0 / count
        path = folder / f"cranium_{i:02}.json"
        path.write_text(json.dumps(scene, indent=2))
        files.append(os.fspath(path))
    return files


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--scenes", type=int, default=16)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--cli", default=os.fspath(REPO / "target/release/volao"))
    args = parser.parse_args()

    import volao
    from dask.distributed import Client, LocalCluster

    spec = importlib.util.spec_from_file_location("cohort_dask", REPO / "examples/cohort_dask.py")
    cohort = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cohort)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "scenes").mkdir()
        scenes = make_scenes(tmp / "scenes", args.scenes, args.size)

        start = time.perf_counter()
        run = subprocess.run([args.cli, "batch", *scenes, "--out", os.fspath(tmp / "batch")],
                             capture_output=True, text=True)
        batch_s = time.perf_counter() - start
        if run.returncode != 0:
            sys.exit(f"volao batch failed:\n{run.stderr}")

        start = time.perf_counter()
        with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                          host="127.0.0.1", dashboard_address=None) as cluster, \
                Client(cluster) as client:
            client.wait_for_workers(args.workers)
            ready = time.perf_counter()
            results, failures = cohort.render_cohort(client, scenes, os.fspath(tmp / "dask"))
            dask_s = time.perf_counter() - ready
        dask_total_s = time.perf_counter() - start
        if failures:
            sys.exit(f"the Dask run failed: {failures}")
        same = all((tmp / "batch" / f"{Path(s).stem}.png").read_bytes()
                   == (tmp / "dask" / f"{Path(s).stem}.png").read_bytes() for s in scenes)
        if not same:
            sys.exit("the Dask images differ from volao batch's")

        adapter = volao.adapter()
        n = len(scenes)
        print(f"### Cohorts: {n} cranium scenes at {args.size}² with 14-ray LAO "
              f"({datetime.date.today().isoformat()}, {adapter}; {os.cpu_count()}-core machine)\n")
        print("| run | wall time | scenes per minute |")
        print("|---|---|---|")
        print(f"| `volao batch` (one process, one device) | {batch_s:.1f} s | {n * 60 / batch_s:.1f} |")
        print(f"| Dask, {args.workers} worker processes (rendering, workers up) | {dask_s:.1f} s "
              f"| {n * 60 / dask_s:.1f} |")
        print(f"| Dask, the same with the cluster's start and stop | {dask_total_s:.1f} s "
              f"| {n * 60 / dask_total_s:.1f} |")
        print(f"\nBoth wrote the same {n} PNGs, byte for byte.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
