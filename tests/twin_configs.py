"""The shipped simulated-lab configs switched to the *ideal* twin, for tests of plumbing.

The shipped configs run the realistic twin (its own hidden truth, realistic instruments:
sim/truth.py). Tests that check that a reading travels unchanged from the simulated
instrument to the store, the CLI or the TUI compare against the prediction's own model,
so they use ``[sim.twin] mode = "ideal"``: the instruments read that model.
"""

from __future__ import annotations

from pathlib import Path

from goniolab.config import configs_dir

REALISTIC = 'mode = "realistic"'
IDEAL = 'mode = "ideal"'


def ideal(text: str) -> str:
    """A lab config's text with the ideal twin."""
    assert REALISTIC in text, "config has no [sim.twin] mode line"
    return text.replace(REALISTIC, IDEAL)


def ideal_config(tmp_path: Path, base: str = "lab-sim.toml", name: str = "") -> Path:
    """A copy of ``configs/<base>`` with the ideal twin, in ``tmp_path``."""
    path = tmp_path / (name or f"ideal-{base}")
    path.write_text(ideal((configs_dir() / base).read_text()))
    return path
