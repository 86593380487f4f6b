"""goniolab: goniospectrophotometer and glossmeter control with a roughness-based model.

Predicts the in-plane BRDF and the ISO 2813 gloss of a coating from its measured height map
(Wittmann et al. 2021, Prog. Org. Coat. 156, 106247) and compares the prediction, live,
with measurements from the instruments.

``__version__`` is looked up in the installed metadata on first use only: reading the
distribution metadata walks ``sys.path`` (tens of milliseconds), which ``goniolab --help``
should not pay.
"""

from __future__ import annotations

__all__ = ["__version__"]


def __getattr__(name: str) -> str:
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("goniolab")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree
            value = "0.0.0+unknown"
        globals()["__version__"] = value
        return value
    raise AttributeError(f"module 'goniolab' has no attribute {name!r}")
