"""The numba kernels compile once: cached on disk, and still usable without a cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

_GLOSS = (
    "import json, numpy as np\n"
    "from goniolab.optics.heightmap import HeightMap\n"
    "from goniolab.optics.surface import Surface\n"
    "from goniolab.optics.facet import FacetModel\n"
    "from goniolab.optics import _kernels as K\n"
    "z = np.add.outer(np.sin(np.arange(64) / 3.0), np.cos(np.arange(64) / 5.0)) * 0.05\n"
    "m = FacetModel(Surface.from_heightmap(HeightMap(z_um=z, dx_um=1.0, dy_um=1.0)))\n"
    "print(json.dumps({'gloss': m.gloss((60,)), 'cached': K.CACHED}))\n"
)


def _run(code: str, cache_dir: Path) -> dict[str, object]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    )
    result: dict[str, object] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


@pytest.mark.slow
def test_kernels_are_compiled_once_into_the_cache_directory(tmp_path: Path) -> None:
    first = _run(_GLOSS, tmp_path)
    index = sorted(p.name for p in tmp_path.rglob("*.nbi"))
    assert any(name.startswith("_kernels.rect_response_numba") for name in index), index
    assert first["cached"] is True
    stamps = {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*.nbc")}
    second = _run(_GLOSS, tmp_path)  # loads the machine code: writes nothing new
    assert second == first
    assert {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*.nbc")} == stamps


def test_a_kernel_without_any_cache_location_is_compiled_in_process(tmp_path: Path) -> None:
    # numba finds no cache locator for source it cannot locate (here: exec'd text) and
    # raises at decoration; njit_cached then compiles without a cache
    code = (
        "import json\n"
        "from goniolab.optics import _kernels as K\n"
        "ns = {}\n"
        "exec(compile('def f(x):\\n    return 2.0 * x + 1.0\\n', '<text>', 'exec'), ns)\n"
        "before = K.CACHED\n"
        "g = K.njit_cached(nogil=True)(ns['f'])\n"
        "print(json.dumps({'value': g(3.0), 'before': before, 'cached': K.CACHED}))\n"
    )
    assert _run(code, tmp_path) == {"value": 7.0, "before": True, "cached": False}
