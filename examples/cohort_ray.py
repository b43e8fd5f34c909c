"""Render a cohort of volao scene files on Ray: each worker process holds one device.

    python examples/cohort_ray.py SCENE.json|DIR ... --out DIR [--cpus 2]
    python examples/cohort_ray.py DIR --out DIR --address auto --gpus

Without --address it starts a local Ray instance (`ray.init(num_cpus=N)`). With --gpus
each task is `num_gpus=1`: Ray sets CUDA_VISIBLE_DEVICES per task, so tasks on a
machine with several GPUs each get their own. A failing scene is retried once
(`max_retries=1, retry_exceptions=True`), then reported with its reason; the exit code
is 1 if any scene failed. See docs/cohorts.md.
"""

from __future__ import annotations

import sys
import time

import ray


@ray.remote(max_retries=1, retry_exceptions=True)
def render_task(scene, out_dir):
    from volao.cohort import render_scene_file

    return render_scene_file(scene, out_dir)


def render_cohort(scenes, out_dir, gpu=False):
    """Renders `scenes` on the Ray cluster into `out_dir`, each retried at most once.
    Returns (results, failures) with every scene in exactly one of them."""
    task = render_task.options(num_gpus=1) if gpu else render_task
    refs = {task.remote(scene, out_dir): scene for scene in scenes}
    results, failures = [], []
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        try:
            results.append(ray.get(done[0]))
        except ray.exceptions.RayError as e:
            # A task's own exception comes back as its cause; a lost worker as itself.
            failures.append((refs[done[0]], str(getattr(e, "cause", None) or e)))
    return results, failures


def main(argv=None):
    from volao.cohort import arguments, report, scene_files

    parser = arguments(__doc__.splitlines()[0])
    parser.add_argument("--address", help="a running Ray cluster (e.g. auto)")
    parser.add_argument("--cpus", type=int, default=2, help="local Ray CPUs")
    args = parser.parse_args(argv)

    scenes = scene_files(args.inputs)
    if args.address:
        ray.init(address=args.address)
    else:
        ray.init(num_cpus=args.cpus, include_dashboard=False)
    try:
        start = time.perf_counter()
        results, failures = render_cohort(scenes, args.out, gpu=args.gpus)
        print(report(scenes, results, failures, time.perf_counter() - start))
    finally:
        ray.shutdown()
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
