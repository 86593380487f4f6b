"""The surface and model options every ``predict`` sub-command (and ``render``) shares:
``MAP``, ``--n``, ``--step-um``, ``--slope-method``, ``--weighting``, ``--masking``,
``--model``, ``--wavelength-nm``, parsed into a
:class:`goniolab.app.predictions.SurfaceRequest`."""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import TYPE_CHECKING

from goniolab.model_registry import DEFAULT_MODEL, model_help, model_names

if TYPE_CHECKING:  # numpy and the optics load when a command runs, not at --help
    from goniolab.app.predictions import SurfaceRequest

__all__ = ["ModelProgress", "add_surface_options", "parse_index", "surface_request"]


class ModelProgress:
    """Progress on stderr for model work that runs over ~2 s (only on a terminal)."""

    def __init__(self) -> None:
        self.start = time.monotonic()
        self.shown = False

    def __call__(self, done: int, total: int, what: str) -> None:
        if not sys.stderr.isatty() or time.monotonic() - self.start < 2.0:
            return
        self.shown = True
        end = "\n" if done >= total else ""
        print(
            f"\r{what}: {100 * done // max(total, 1):3d} % ({done}/{total})",
            end=end,
            file=sys.stderr,
            flush=True,
        )


def parse_index(text: str) -> complex:
    """Parse ``--n``: a real index (``1.55``) or ``n+kj`` for conductors (``0.27+3.41j``).

    ``i`` is accepted for ``j``. Requires n > 0 and k >= 0.
    """
    raw = text.strip().replace(" ", "")
    try:
        value = complex(raw.replace("i", "j"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--n {text!r}: not a number or complex index like 0.27+3.41j"
        ) from None
    if not (math.isfinite(value.real) and math.isfinite(value.imag)):
        raise argparse.ArgumentTypeError(f"--n {text!r}: must be finite")
    if value.real <= 0 or value.imag < 0:
        raise argparse.ArgumentTypeError(f"--n {text!r}: needs n > 0 and k >= 0")
    return value


def surface_request(args: argparse.Namespace) -> SurfaceRequest:
    """The surface and model options of a ``predict`` command (:func:`add_surface_options`)."""
    from goniolab.app.predictions import SurfaceRequest

    return SurfaceRequest(
        args.map,
        n=args.n,
        step_um=args.step_um,
        slope_method=args.slope_method,
        weighting=args.weighting,
        masking=args.masking,
        model=args.model,
        wavelength_nm=args.wavelength_nm,
    )


def add_surface_options(p: argparse.ArgumentParser, *, many: bool = False) -> None:
    """``MAP`` (``many``: one or more) and the model options, and ``--json``."""
    if many:
        p.add_argument("map", metavar="MAP", nargs="+", help="height-map files or sample:NAME")
    else:
        p.add_argument("map", metavar="MAP", help="height-map file or sample:NAME")
    p.add_argument(
        "--n",
        type=parse_index,
        default=complex(1.55),
        help="refractive index, or n+kj for metals, e.g. 0.27+3.41j",
    )
    p.add_argument(
        "--step-um", type=float, default=None, help="lateral step, um, of a file that carries none"
    )
    p.add_argument(
        "--slope-method",
        choices=("forward", "central", "plane8"),
        default="forward",
        help="facet slopes from the map: forward differences (the seed's), central "
        "differences, or the least-squares plane through 3 x 3 points (smooths pixel noise)",
    )
    p.add_argument(
        "--weighting",
        choices=("radiometric", "seed"),
        default="radiometric",
        help="facet weight: radiometric (docs/PHYSICS.md) or the seed's Fresnel-only",
    )
    p.add_argument(
        "--masking",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="Smith masking-shadowing from the measured slopes (default: on)",
    )
    p.add_argument(
        "--model",
        choices=model_names(),
        default=DEFAULT_MODEL,
        help=model_help(),
    )
    p.add_argument(
        "--wavelength-nm",
        type=float,
        default=None,
        help="wavelength of every response (default: gloss weighted over CIE C x V(lambda), "
        "BRDFs at 550 nm)",
    )
    p.add_argument("--json", action="store_true", help="machine-readable output")
