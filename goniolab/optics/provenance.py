"""Which model computed a number: one question for every reflectance model.

:func:`provenance_of` answers, for any :class:`~goniolab.optics.models.ReflectanceModel`
and one instrument geometry, with a :class:`~goniolab.optics.physical.Provenance`: the
model whose formulas produced the reading (``facet``, ``kirchhoff``, ``rayleigh-rice``,
``analytic-<kind>``) and the notes the user must see (a validity limit met and the model
used instead, light the map cannot resolve, an energy scale). The wave models and ``auto``
answer for themselves (:meth:`PhysicalOpticsModel.provenance`,
:meth:`AutoModel.provenance`); a facet or analytic model is its own model.

The CLI prints the notes on stderr and puts ``model`` and ``warnings`` in ``--json``; the
scan, TUI and store layers call the same function for the readings they show or keep.
The module imports nothing heavy: a model is recognised by its loaded module (no instance
of a class exists before its module is imported).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from goniolab.optics.apertures import (
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
)

__all__ = ["Provenance", "gloss_provenance_of", "model_label", "provenance_of"]


@dataclass(frozen=True)
class Provenance:
    """Which model computed a number, and what the user must know about it.

    ``model``: ``"facet"``, ``"kirchhoff"`` or ``"rayleigh-rice"``, the model whose
    formulas produced the number (not the one asked for); ``notes``: every approximation
    beyond the model's own (validity limits met, light the map cannot resolve, a hand-over
    to another model and why), in words, empty when there is none.
    """

    model: str
    notes: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"model": self.model}
        if self.notes:
            out["warnings"] = list(self.notes)
        return out


def _is_a(obj: Any, module: str, name: str) -> bool:
    mod = sys.modules.get(module)
    return mod is not None and isinstance(obj, getattr(mod, name))


def model_label(model: Any) -> str:
    """The name of a model as a whole: ``facet``, ``kirchhoff``, ``rayleigh-rice``,
    ``auto``, ``analytic-<kind>``, else its class name."""
    if _is_a(model, "goniolab.optics.analytic", "AnalyticModel"):
        return f"analytic-{model.kind}"
    if _is_a(model, "goniolab.optics.facet", "FacetModel"):
        return "facet"
    kind = getattr(model, "kind", None)
    return kind if isinstance(kind, str) else type(model).__name__


def provenance_of(
    model: Any,
    theta_i_deg: float,
    theta_r_deg: float,
    source: Aperture,
    receptor: Aperture,
    *,
    wavelengths_nm: Sequence[float] | None = None,
) -> Provenance:
    """The :class:`Provenance` of ``model``'s reading at one geometry (the model that
    computes it and the notes)."""
    if hasattr(model, "provenance"):
        out = model.provenance(
            theta_i_deg, theta_r_deg, source, receptor, wavelengths_nm=wavelengths_nm
        )
        assert isinstance(out, Provenance)
        return out
    return Provenance(model_label(model))


def gloss_provenance_of(
    model: Any, angles_deg: Sequence[int] = (20, 60, 85)
) -> dict[int, Provenance]:
    """:func:`provenance_of` of each ISO 2813 geometry (over the gloss wavelengths)."""
    if hasattr(model, "gloss_provenance"):
        out: dict[int, Provenance] = model.gloss_provenance(angles_deg)
        return out
    return {
        int(t): provenance_of(model, int(t), int(t), ISO2813_SOURCE, ISO2813_RECEPTOR[int(t)])
        for t in angles_deg
    }
