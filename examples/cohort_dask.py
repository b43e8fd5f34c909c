"""Render a cohort of volao scene files on Dask: each worker process holds one device.

    python examples/cohort_dask.py SCENE.json|DIR ... --out DIR [--workers 2]
    python examples/cohort_dask.py DIR --out DIR --scheduler tcp://host:8786 --gpus

Without --scheduler it starts a LocalCluster on this machine (loopback only) with one
single-threaded worker process per --workers. With --gpus each task asks for the
worker resource GPU=1: start each worker with `--resources GPU=1` (one per GPU, with
CUDA_VISIBLE_DEVICES or the Vulkan device of its GPU) and no two tasks share a device.
A failing scene is retried once (`retries=1`), then reported with its reason; the exit
code is 1 if any scene failed. See docs/cohorts.md.
"""

from __future__ import annotations

import sys
import time


def render_cohort(client, scenes, out_dir, gpu=False):
    """Renders `scenes` on `client`'s workers into `out_dir`, each retried at most once.
    Returns (results, failures) with every scene in exactly one of them."""
    from dask.distributed import as_completed

    from volao.cohort import render_scene_file

    options = {"resources": {"GPU": 1}} if gpu else {}
    futures = client.map(render_scene_file, scenes, out_dir=out_dir, retries=1,
                         pure=False, **options)
    scene_of = {f.key: s for f, s in zip(futures, scenes)}
    results, failures = [], []
    for future in as_completed(futures):
        if future.status == "error":
            failures.append((scene_of[future.key], str(future.exception())))
        else:
            results.append(future.result())
    return results, failures


def main(argv=None):
    from dask.distributed import Client, LocalCluster

    from volao.cohort import arguments, report, scene_files

    parser = arguments(__doc__.splitlines()[0])
    parser.add_argument("--scheduler", help="address of a running Dask scheduler")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes")
    args = parser.parse_args(argv)

    scenes = scene_files(args.inputs)
    if args.scheduler:
        client, cluster = Client(args.scheduler), None
    else:
        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None,
                               resources={"GPU": 1} if args.gpus else None)
        client = Client(cluster)
    try:
        start = time.perf_counter()
        results, failures = render_cohort(client, scenes, args.out, gpu=args.gpus)
        print(report(scenes, results, failures, time.perf_counter() - start))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return 1 if failures else 0


# Dask's worker processes import this file again: run only as a script.
if __name__ == "__main__":
    sys.exit(main())
