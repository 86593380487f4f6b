"""Fill the on-disk caches the suite's processes share, once, before the xdist workers start.

On a fresh clone every process that first calls a numba kernel compiles it (``cache=True``
then stores it next to the source), and the realistic twin builds its response tables
(stored in the user cache dir). Under ``pytest -n 2`` both workers, and the ``goniolab``
subprocesses the end-to-end tests start, did that at once: tens of seconds each, enough
for a subprocess scan to miss a test's time limit. The controller does it here once, on
the models and the default sample the tests use; everything later loads the results.
"""

from __future__ import annotations

import numpy as np


def warm_caches() -> None:
    """Compile the facet, Kirchhoff and Rayleigh-Rice kernels on their usual paths and
    build the default twin's truth (both cached on disk)."""
    from goniolab.config import LabConfig
    from goniolab.lab_wiring import sample_truth
    from goniolab.model_cache import model_for

    tr = np.arange(0.0, 71.0, 1.0)
    for spec, kind, masking in (
        ("sample:wittmann-3", "facet", True),
        ("sample:wittmann-3", "facet", False),
        ("sample:wittmann-3", "auto", True),
        ("sample:gloss-sq50-l2", "kirchhoff", True),
        ("sample:gloss-sq50-l2", "rayleigh-rice", True),
    ):
        model = model_for(spec, model=kind, masking=masking)
        model.luminance_pct(45.0, tr)
        model.luminance_pct(45.0, [44.0, 45.0])
        model.gloss()
    sample_truth(LabConfig())
