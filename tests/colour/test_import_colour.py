"""colour-science without its plotting package until it is used (goniolab/lazy_imports.py)."""

from __future__ import annotations

import subprocess
import sys

CODE = """
import sys
from goniolab.lazy_imports import import_colour
colour = import_colour()
assert "matplotlib" not in sys.modules, "colour.plotting imported matplotlib"
assert float(colour.SDS_ILLUMINANTS["D65"][560]) > 0  # the colour science is all there
f = colour.plotting.plot_single_sd  # first use: the real plotting package
import colour.plotting as real
assert real.plot_single_sd is f and "matplotlib" in sys.modules
assert import_colour() is colour
print("ok")
"""


def test_colour_imports_without_plotting_and_plotting_still_works() -> None:
    out = subprocess.run(
        [sys.executable, "-c", CODE], capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


THREADS = """
import threading
import time
from goniolab.lazy_imports import import_colour
from sim.truth import luminance_weights

got, errors = [], []

def use(k):
    time.sleep(0.15 * k)  # the others ask while the first one's import runs
    try:
        if k % 2:
            got.append(float(import_colour().MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
                             .values[:, 1].max()))
        else:
            got.append(float(luminance_weights().sum()))
    except Exception as exc:
        errors.append(repr(exc))

threads = [threading.Thread(target=use, args=(k,)) for k in range(4)]
for t in threads:
    t.start()
for t in threads:
    t.join()
assert not errors, errors
print(sorted(round(v, 6) for v in got))
"""


def test_threads_that_import_colour_at_once_all_get_the_whole_module() -> None:
    # a scan's first reading: the twin's spectrum and the model's colour import colour in
    # worker threads at once; the one that did not import it used to take the half-built
    # module from sys.modules (AttributeError: ... has no attribute 'MSDS_CMFS')
    out = subprocess.run(
        [sys.executable, "-c", THREADS], capture_output=True, text=True, timeout=120,
        check=False,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    # y-bar peaks at 1.0 (CIE 1931, 555 nm); the luminance weights sum to 1
    assert out.stdout.strip() == "[1.0, 1.0, 1.0, 1.0]"
