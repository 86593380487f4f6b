"""Help that teaches (issue 27, item 2): every command's examples and one help formatter.

Every ``goniolab ... --help`` ends with an ``examples:`` section taken from
:data:`EXAMPLES` (keyed by the command's words, ``"predict gloss"``), and every option
with a default says it as ``(default: X)``. ``tests/test_help.py`` walks every command:
each one has examples, each example parses with the real parser (so an example cannot
name an option that is gone), and every option with a default shows it.

Kept in one table rather than beside each parser so that the commands' modules stay
free of long text blocks; :func:`apply` attaches them after the commands registered.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from typing import Any

__all__ = ["EXAMPLES", "RUN_HELP", "HelpFormatter", "apply", "walk"]

#: The help of every RUN argument.
RUN_HELP = "run id, as 'goniolab runs list' shows it"

_SIM = "configs/lab-sim.toml"

#: Two or three examples per command, ``goniolab ...  # what it does``.
EXAMPLES: dict[str, list[str]] = {
    "": [
        "goniolab samples save wittmann-3 scan.sur      # a height-map file to start from",
        "goniolab predict gloss scan.sur --n 1.55       # its predicted G20/G60/G85",
        f"goniolab tui --config {_SIM} --autostart     # the simulated lab, live",
    ],
    "calibrate": [
        f"goniolab calibrate --config {_SIM}             # mirror and black glass vs certificates",
        f"goniolab calibrate --config {_SIM} --theta 60 --repeats 5 --json",
    ],
    "fit": [
        "goniolab fit colour 3                          # the paint of run 3's sample, fitted",
        "goniolab fit colour 3 --params body.ks_scale,coat.n --save fitted.toml",
    ],
    "fit colour": [
        "goniolab fit colour 3                          # K/S, flakes and coat n vs run 3",
        "goniolab fit colour 3 --params body.ks_scale,coat.n --save fitted.toml",
        "goniolab fit colour 3 --metric de2000 --min-aspecular 15 --json",
    ],
    "gloss": [
        f"goniolab gloss log --config {_SIM} --count 10",
        "goniolab gloss log --port /dev/ttyUSB0 --protocol zgm1120 --count 5",
    ],
    "gloss calibrate": [
        f"goniolab gloss calibrate --config {_SIM}          # 20/60/85 on the working standard",
        f"goniolab gloss calibrate --config {_SIM} --standard black_glass --json",
        "goniolab gloss calibrate --port /dev/ttyUSB0 --protocol zgm1120 --angles 60",
    ],
    "gloss log": [
        f"goniolab gloss log --config {_SIM} --count 10            # 10 readings, stored",
        f"goniolab gloss log --config {_SIM} --interval 5 --sample sample:wittmann-3",
        "goniolab gloss log --port /dev/ttyUSB0 --protocol zgm1120 --count 5   # no config",
    ],
    "lab": [
        f"goniolab lab reset-alarm --config {_SIM}",
        "goniolab lab reset-alarm --config configs/lab-real-example.toml --json",
    ],
    "lab reset-alarm": [
        f"goniolab lab reset-alarm --config {_SIM}      # clear a latched alarm, nothing moves",
        "goniolab lab reset-alarm --config configs/lab-real-example.toml --json",
    ],
    "plot": [
        "goniolab plot 1 --out run1.png                 # run 1: measured, predicted, residuals",
        "goniolab plot 1 --out run1.svg --log           # luminance on a log axis",
        "goniolab plot 1 --store lab.sqlite --out run1.pdf",
    ],
    "predict": [
        "goniolab predict stats sample:wittmann-5",
        "goniolab predict gloss scan.sur --n 1.55",
        "goniolab predict brdf scan.sur --theta-i 45 --theta-r 0:70:1",
    ],
    "predict stats": [
        "goniolab predict stats sample:wittmann-5       # Ra, Sq, Sdq, h_r",
        "goniolab predict stats map.npy --step-um 0.5   # a map without a lateral step",
    ],
    "predict gloss": [
        "goniolab predict gloss scan.sur --n 1.55       # G20/G60/G85, haze, DOI",
        "goniolab predict gloss maps/*.sur --json > gloss.jsonl   # many maps, JSON Lines",
        "goniolab predict gloss sample:wittmann-3 --model kirchhoff",
    ],
    "predict brdf": [
        "goniolab predict brdf scan.sur --theta-i 45 --theta-r 0:70:1",
        "goniolab predict brdf sample:wittmann-1 --theta-r 40,45,50 --point   # exact directions",
        "goniolab predict brdf scan.sdf --detector-deg 6 --source-deg 6 --out brdf.nc",
    ],
    "predict albedo": [
        "goniolab predict albedo sample:wittmann-3      # at 0, 30, 60 and 85 deg",
        "goniolab predict albedo scan.sur --theta-i 0:80:10 --json",
    ],
    "predict colour": [
        "goniolab predict colour sample:silver-metallic   # L*a*b* at the E2194 angles",
        "goniolab predict colour scan.sur --paint paint.toml --theta-r 0:70:5 --illuminant A",
        "goniolab predict colour sample:solid-red --compare measured.csv",
    ],
    "render": [
        "goniolab render sample:silver-metallic --out panel.png --lamps 2",
        "goniolab render sample:pearl --out sphere.png --shape sphere --lamps 2",
        "goniolab render scan.sur --out panel.png --n 1.5 --size 256",
    ],
    "runs": [
        "goniolab runs list",
        "goniolab runs show 1",
        "goniolab runs export 1 -o run1.csv",
    ],
    "runs list": [
        "goniolab runs list --limit 10                  # the 10 newest runs",
        "goniolab runs list --operator ana --tag batch-7",
        "goniolab runs list --search wittmann --json",
    ],
    "runs show": [
        "goniolab runs show 1",
        "goniolab runs show 1 --json --store lab.sqlite",
    ],
    "runs colour": [
        "goniolab runs colour 3                         # measured vs predicted colour",
        "goniolab runs colour 3 --vs 4 --illuminant A   # two runs, also under illuminant A",
    ],
    "runs spectra": [
        "goniolab runs spectra 3 -o spectra.csv",
        "goniolab runs spectra 3 -o spectra.parquet --which measured",
    ],
    "runs export": [
        "goniolab runs export 1 -o run1.csv             # format from the suffix",
        "goniolab runs export 1 --format parquet -o run1.parquet",
        "goniolab runs export 1 --json | head           # to stdout",
    ],
    "runs migrate": [
        "goniolab runs migrate --from lab-pc.sqlite --store postgresql://lab@dbhost/goniolab",
        "goniolab runs migrate --from lab-pc.sqlite --store shared.sqlite --json",
    ],
    "runs import": [
        "goniolab runs import run1.json                 # a JSON export read back",
        "goniolab runs import lab-a/*.json --store shared.sqlite --json",
    ],
    "runs annotate": [
        "goniolab runs annotate 1 --operator ana --sample-id P-0042",
        'goniolab runs annotate 1 --tag batch-7 --note "re-measured after cleaning"',
        "goniolab runs annotate 1 --untag draft",
    ],
    "samples": [
        "goniolab samples                               # the built-in samples",
        "goniolab samples save wittmann-3 scan.sur      # a Digital Surf file to try on",
        "goniolab samples save gaussian-s0.05 scan.sdf --size 1024 --step-um 0.5",
    ],
    "samples save": [
        "goniolab samples save wittmann-3 scan.sur",
        "goniolab samples save wittmann-5 map.npy --size 256   # + map.npy.json sidecar",
        "goniolab samples save gaussian-s0.05 scan.sdf --size 1024 --step-um 0.5",
    ],
    "scan": [
        f"goniolab scan --config {_SIM} --sample sample:wittmann-3 --theta-r 0:70:1",
        f"goniolab scan --config {_SIM} --sample scan.sur --theta-r 30:60:10 --time-scale 0",
        "goniolab scan resume 4                         # continue interrupted run 4",
    ],
    "scan resume": [
        "goniolab scan resume 4",
        "goniolab scan resume 4 --store lab.sqlite --time-scale 0",
    ],
    "sim": [
        "goniolab sim serve --config configs/lab-sim-wire.toml",
        "goniolab sim serve --config configs/lab-sim-wire.toml --json --time-scale 0",
        "goniolab sim cache                  # the twin's table cache: where, how big",
    ],
    "sim cache": [
        "goniolab sim cache",
        "goniolab sim cache --prune --max-mb 1000 --other-versions-age-h 0",
        "goniolab sim cache --clear",
    ],
    "sim serve": [
        "goniolab sim serve --config configs/lab-sim-wire.toml   # until Ctrl-C",
        "goniolab sim serve --config configs/lab-sim-wire.toml --json --time-scale 0",
    ],
    "tui": [
        f"goniolab tui --config {_SIM}",
        f"goniolab tui --config {_SIM} --autostart --gloss-every 5   # what make run does",
        f"goniolab tui --config {_SIM} --sample sample:solid-red --time-scale 0",
    ],
}


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """The help of every goniolab command.

    - An option with a default says it, ``(default: X)``, unless its help already does.
    - An optional sub-command reads ``[resume ...]`` in the usage, not ``resume ...``.
    - Descriptions lose their reStructuredText markup (they come from docstrings).
    - Descriptions are wrapped as usual; an epilog (the examples) and a text with indented
      lines (a table of keys) are kept as written.
    """

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        text = _plain(text)
        if text.startswith("examples:") or "\n  " in text:
            return super()._fill_text(text, width, indent)  # laid out by hand: kept
        return argparse.HelpFormatter._fill_text(self, text, width, indent)

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if (
            action.option_strings
            and action.nargs != 0
            and action.default not in (None, argparse.SUPPRESS)
            and "(default: " not in text
        ):
            shown = show_default(action.default).replace("%", "%%")
            text = f"{text} (default: {shown})" if text else f"(default: {shown})"
        return text or None

    def _format_args(self, action: argparse.Action, default_metavar: str) -> str:
        text = super()._format_args(action, default_metavar)
        if action.nargs == argparse.PARSER and not action.required:
            return f"[{text}]"
        return text


def _plain(text: str) -> str:
    """Text without reStructuredText markup (descriptions taken from docstrings):
    ``:func:`x``` and ````x```` read as ``x``."""
    import re

    return re.sub(r"``([^`]+)``", r"\1", re.sub(r":\w+:`~?([^`]+)`", r"\1", text))


def show_default(value: Any) -> str:
    """A default as a user types it: ``1.55`` for ``(1.55+0j)``, ``20 60 85`` for a list."""
    if isinstance(value, complex):
        return f"{value.real:g}" if value.imag == 0 else f"{value.real:g}{value.imag:+g}j"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list | tuple):
        return " ".join(show_default(v) for v in value) if value else "none"
    return str(value)


def walk(
    parser: argparse.ArgumentParser, words: tuple[str, ...] = ()
) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """Every parser under ``parser`` (itself first) with its command words."""
    yield " ".join(words), parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield from walk(child, (*words, name))


def apply(parser: argparse.ArgumentParser) -> None:
    """Give every parser under ``parser`` the help formatter and its examples."""
    for words, p in walk(parser):
        p.formatter_class = HelpFormatter
        lines = EXAMPLES.get(words)
        if lines and not p.epilog:
            p.epilog = "examples:\n" + "\n".join(f"  {line}" for line in lines)
