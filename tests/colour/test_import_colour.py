"""colour-science without its plotting package until it is used (goniolab/_lazy.py)."""

from __future__ import annotations

import subprocess
import sys

CODE = """
import sys
from goniolab._lazy import import_colour
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
