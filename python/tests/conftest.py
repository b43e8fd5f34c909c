"""Shared fixtures: the real volumes in ../shared/data, the `volao` CLI the Python results
are compared with, and a PNG decoder independent of volao."""

from __future__ import annotations

import os
import struct
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def data() -> Path:
    """The shared test volumes (``$VOLAO_DATA`` or ``../shared/data``); never skipped."""
    path = Path(os.environ.get("VOLAO_DATA", REPO.parent / "shared" / "data"))
    if not (path / "README.md").is_file():
        pytest.fail(f"the shared test volumes are missing: expected {path}/README.md")
    return path


@pytest.fixture(scope="session")
def volao_cli() -> Path:
    """The `volao` binary (``$VOLAO_BIN``, else the one `cargo test` built)."""
    path = Path(os.environ.get("VOLAO_BIN", REPO / "target" / "debug" / "volao"))
    if not path.is_file():
        pytest.fail(f"the volao CLI is missing: expected {path} (run `cargo build` or set VOLAO_BIN)")
    return path


def run_cli(cli: Path, *args, ok: bool = True) -> subprocess.CompletedProcess:
    """Runs the CLI; with `ok`, fails the test with its stderr when it fails."""
    out = subprocess.run([os.fspath(cli), *map(os.fspath, args)], capture_output=True,
                         text=True, timeout=600)
    if ok and out.returncode != 0:
        pytest.fail(f"volao {' '.join(map(str, args))} failed:\n{out.stderr}")
    return out


def read_png(path: Path) -> np.ndarray:
    """Decodes an 8-bit RGBA, non-interlaced PNG (what volao writes) to (H, W, 4) uint8."""
    raw = Path(path).read_bytes()
    assert raw[:8] == b"\x89PNG\r\n\x1a\n", f"{path}: not a PNG"
    pos, idat, header = 8, b"", None
    while pos < len(raw):
        (length,) = struct.unpack(">I", raw[pos:pos + 4])
        kind, body = raw[pos + 4:pos + 8], raw[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
    width, height, depth, colour, _, _, interlace = header
    assert (depth, colour, interlace) == (8, 6, 0), f"{path}: not 8-bit RGBA non-interlaced"
    rows = zlib.decompress(idat)
    stride, bpp = width * 4, 4
    out = np.zeros((height, stride), dtype=np.uint8)
    prev = np.zeros(stride, dtype=np.int32)
    for y in range(height):
        kind = rows[y * (stride + 1)]
        line = np.frombuffer(rows, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32)
        cur = np.zeros(stride, dtype=np.int32)
        for x in range(stride):
            a = cur[x - bpp] if x >= bpp else 0
            b = prev[x]
            c = prev[x - bpp] if x >= bpp else 0
            if kind == 0:
                p = 0
            elif kind == 1:
                p = a
            elif kind == 2:
                p = b
            elif kind == 3:
                p = (a + b) // 2
            else:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
            cur[x] = (line[x] + p) & 0xFF
        out[y] = cur
        prev = cur
    return out.reshape(height, width, 4)
