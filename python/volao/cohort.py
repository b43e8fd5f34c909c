"""Cohorts on an existing distributed engine (Dask, Ray): the unit of work is one scene
file rendered to one PNG, run on a worker that holds the process's one device.

volao has no scheduler of its own: the engine places the tasks, retries a failed one
(at most once, as ``examples/cohort_dask.py`` and ``examples/cohort_ray.py`` ask it to)
and hands every failure back; :func:`report` lists them, so nothing is dropped silently.
Outputs are written beside nothing else and skipped when they exist, so a cohort run
that was interrupted resumes like ``volao batch``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Iterable, List, Sequence, Tuple

from ._volao import Scene, VolaoError

__all__ = ["arguments", "render_scene_file", "report", "scene_files"]


def arguments(description: str) -> argparse.ArgumentParser:
    """The flags every cohort script takes: scene files or folders, ``--out``, ``--gpus``;
    an engine adds its own."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("inputs", nargs="+", help="scene files or folders of them")
    parser.add_argument("--out", required=True, help="folder for NAME.png")
    parser.add_argument("--gpus", action="store_true", help="each task needs one GPU")
    return parser


def scene_files(inputs: Iterable[str | os.PathLike]) -> List[str]:
    """The scene files the inputs name: a ``.json`` file as it is, a folder as its
    ``.json`` files in name order (``volao batch``'s rule)."""
    files: List[str] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.iterdir() if p.suffix.lower() == ".json")
            if not found:
                raise VolaoError(f"{path}: no scene files (.json) in this folder")
            files.extend(os.fspath(p) for p in found)
        else:
            files.append(os.fspath(path))
    stems = [Path(f).stem for f in files]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise VolaoError(
            f"scenes named {', '.join(twice)} would write the same PNG: give scenes distinct names"
        )
    return files


def render_scene_file(scene: str | os.PathLike, out_dir: str | os.PathLike) -> dict:
    """Renders one scene file to ``OUT_DIR/NAME.png`` (the bytes ``volao render`` and
    ``volao batch`` write for it), on this process's device. Skipped when the PNG
    exists. Each attempt is recorded as a line in ``OUT_DIR/.attempts/NAME``, so a
    retry can be seen. Raises ``VolaoError`` naming the scene file when it fails.

    Returns ``{"scene", "png", "skipped", "seconds", "device"}``.
    """
    out = Path(out_dir)
    name = Path(scene).stem
    png = out / f"{name}.png"
    attempts = out / ".attempts"
    attempts.mkdir(parents=True, exist_ok=True)
    with open(attempts / name, "a", encoding="utf-8") as log:
        log.write(f"pid {os.getpid()} at {time.time():.3f}\n")
    if png.exists():
        return {"scene": os.fspath(scene), "png": os.fspath(png), "skipped": True,
                "seconds": 0.0, "device": None}
    start = time.perf_counter()
    try:
        image = Scene.load(scene).render()
    except Exception as e:  # every failure goes back to the engine, named
        raise VolaoError(f"{os.fspath(scene)}: {e}") from None
    # Written beside and renamed into place: an interrupted run leaves no partial PNG.
    partial = out / f".partial.{name}.png"
    image.save(partial)
    os.replace(partial, png)
    return {"scene": os.fspath(scene), "png": os.fspath(png), "skipped": False,
            "seconds": time.perf_counter() - start, "device": image.info.get("device")}


def report(scenes: Sequence[str], results: Sequence[dict],
           failures: Sequence[Tuple[str, str]], seconds: float) -> str:
    """The run's summary: one line per failed scene (file and reason), then the counts.
    Every scene is either a result or a failure; a scene in neither is reported too."""
    lines = [f"failed: {scene}: {reason}" for scene, reason in failures]
    accounted = {r["scene"] for r in results} | {s for s, _ in failures}
    lines += [f"lost: {s}: no result and no failure came back" for s in scenes
              if os.fspath(s) not in accounted]
    rendered = sum(1 for r in results if not r["skipped"])
    skipped = len(results) - rendered
    rate = f" ({rendered * 60.0 / seconds:.1f} scenes per minute)" if rendered and seconds > 0 else ""
    lines.append(
        f"cohort: {len(scenes)} scenes: {rendered} rendered, {skipped} skipped (outputs exist), "
        f"{len(failures)} failed, in {seconds:.1f} s{rate}"
    )
    return "\n".join(lines)
