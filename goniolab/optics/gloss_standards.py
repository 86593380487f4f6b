"""What a glossmeter, a haze meter and a DOI meter read from a reflectance model.

:func:`gloss_report` evaluates any :class:`goniolab.optics.models.ReflectanceModel` with the
standard geometries:

- ISO 2813 / ASTM D523 specular gloss G20, G60, G85 (``model.gloss``), and the D523 rule for
  the geometry to report: 60 deg in general, 20 deg when G60 > 70, 85 deg when G60 < 10.
- ASTM D4039 haze index ``HI = G60 - G20``.
- ASTM E430 (docs/PHYSICS.md, "What the instruments see"):
  method B: gloss at 20 deg with haze receptors at 18.1 and 21.9 deg;
  method A: 30 deg incidence, specular receptor, narrow-angle haze receptors at 28/32 deg,
  wide-angle haze at 25/35 deg, and distinctness of image ``DOI = 100 (Rs - R0.3) / Rs``
  with ``R0.3`` read 0.3 deg off specular with the same receptor as ``Rs``.

Every off-specular reading is ``model.reflected_fraction(theta_i, theta_r, source, receptor)``
(Mihalik eq. 15, source normalised) expressed like gloss, in units of the specular flux of
the ISO 2813 black glass standard at the same incidence (``100 Phi / F(1.567, theta_i)``,
Mihalik eqs. 16-17). A perfectly flat surface therefore reads haze 0 and DOI 100.

The E430 apertures below are from memory (the standard is not among the sources): they are
named module constants so that a user with the standard at hand can correct them.

References
----------
.. [1] ASTM D523, ISO 2813: specular gloss (apertures: Mihalik table 1).
.. [2] ASTM D4039: reflection haze of high-gloss surfaces, HI = G60 - G20.
.. [3] ASTM E430: gloss, haze and distinctness of image of high-gloss surfaces by
   goniophotometry (methods A and B).
.. [4] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 15-17.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from goniolab.optics.apertures import ISO2813_BLACK_GLASS_N, ISO2813_SOURCE, Rect
from goniolab.optics.fresnel import fresnel_dielectric
from goniolab.optics.models import ReflectanceModel

__all__ = [
    "D523_HIGH_GLOSS_G60",
    "D523_LOW_GLOSS_G60",
    "E430_A_ANGLE_DEG",
    "E430_A_DOI_OFFSET_DEG",
    "E430_A_HAZE_RECEPTOR",
    "E430_A_NARROW_HAZE_OFFSET_DEG",
    "E430_A_SOURCE",
    "E430_A_SPECULAR_RECEPTOR",
    "E430_A_WIDE_HAZE_OFFSET_DEG",
    "E430_B_ANGLE_DEG",
    "E430_B_HAZE_OFFSET_DEG",
    "E430_B_HAZE_RECEPTOR",
    "E430_B_SOURCE",
    "E430_B_SPECULAR_RECEPTOR",
    "E430Report",
    "GlossReport",
    "d523_recommended_angle",
    "e430_report",
    "gloss_report",
    "report_provenance",
]

#: ASTM D523: use 20 deg above this G60 (high gloss) ...
D523_HIGH_GLOSS_G60: float = 70.0
#: ... and 85 deg below this G60 (low gloss).
D523_LOW_GLOSS_G60: float = 10.0

# --- ASTM E430 geometry. FROM MEMORY, not checked against the standard: correct here. ---
#: Method B: incidence angle (deg), shared with ISO 2813 20 deg gloss.
E430_B_ANGLE_DEG: float = 20.0
#: Method B source and specular receptor: the ISO 2813 20 deg apertures.
E430_B_SOURCE: Rect = ISO2813_SOURCE
E430_B_SPECULAR_RECEPTOR: Rect = Rect(1.8, 3.6)
#: Method B haze receptors at 20 -/+ 1.9 deg (18.1 and 21.9 deg), 0.4 deg wide in plane.
E430_B_HAZE_OFFSET_DEG: float = 1.9
E430_B_HAZE_RECEPTOR: Rect = Rect(0.4, 3.6)
#: Method A (Hunter Dorigon type): incidence angle (deg).
E430_A_ANGLE_DEG: float = 30.0
#: Method A source slit: narrow in plane so that R0.3 sees nothing of a mirror.
E430_A_SOURCE: Rect = Rect(0.05, 2.5)
#: Method A specular / DOI receptor slit (Rs and R0.3 use the same slit).
E430_A_SPECULAR_RECEPTOR: Rect = Rect(0.14, 2.5)
#: Method A DOI receptor offset from specular (deg).
E430_A_DOI_OFFSET_DEG: float = 0.3
#: Method A haze receptors: narrow-angle at 30 -/+ 2 deg, wide-angle at 30 -/+ 5 deg.
E430_A_NARROW_HAZE_OFFSET_DEG: float = 2.0
E430_A_WIDE_HAZE_OFFSET_DEG: float = 5.0
E430_A_HAZE_RECEPTOR: Rect = Rect(0.4, 2.5)


@dataclass(frozen=True)
class E430Report:
    """ASTM E430 readings; gloss and haze in units of the black-glass specular flux x 100.

    Attributes
    ----------
    gloss_20, haze_18_1, haze_21_9, haze_b
        Method B: specular gloss at 20 deg, the two haze receptors and their mean.
    gloss_30, haze_narrow, haze_wide
        Method A: specular reading Rs at 30 deg, narrow-angle haze (mean of 28 and 32 deg)
        and wide-angle haze (mean of 25 and 35 deg).
    doi
        Distinctness of image ``100 (Rs - R0.3) / Rs`` (0 when Rs = 0).
    """

    gloss_20: float
    haze_18_1: float
    haze_21_9: float
    haze_b: float
    gloss_30: float
    haze_narrow: float
    haze_wide: float
    doi: float


@dataclass(frozen=True)
class GlossReport:
    """ISO 2813 gloss, D4039 haze index, E430 readings and the D523 recommended geometry."""

    G20: float
    G60: float
    G85: float
    haze_index: float
    e430: E430Report
    d523_recommended_angle: int
    #: the model that computed each reading (``"G20"``, ..., ``"e430.gloss_30"``, ...):
    #: ``facet``, ``kirchhoff``, ``rayleigh-rice``, ``analytic-<kind>``
    #: (:func:`goniolab.optics.provenance.provenance_of`)
    models: dict[str, str] = field(default_factory=dict)
    #: the notes of those readings (validity limits, hand-overs, light the map cannot
    #: resolve), ``"G85: ..."``
    warnings: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        """Plain nested dict (JSON-ready)."""
        return asdict(self)


def d523_recommended_angle(g60: float) -> int:
    """ASTM D523 geometry to report: 20 deg if G60 > 70, 85 deg if G60 < 10, else 60 deg."""
    if g60 > D523_HIGH_GLOSS_G60:
        return 20
    if g60 < D523_LOW_GLOSS_G60:
        return 85
    return 60


def _standard_flux(theta_i_deg: float) -> float:
    """Specular flux fraction of the ISO 2813 black glass: F(1.567, theta_i) (Mihalik eq. 16)."""
    return float(fresnel_dielectric(math.cos(math.radians(theta_i_deg)), ISO2813_BLACK_GLASS_N))


def _reading(
    model: ReflectanceModel, theta_i: float, theta_r: float, src: Rect, rec: Rect
) -> float:
    return 100.0 * model.reflected_fraction(theta_i, theta_r, src, rec) / _standard_flux(theta_i)


def e430_report(model: ReflectanceModel) -> E430Report:
    """ASTM E430 methods A and B from ``model.reflected_fraction`` (module docstring), one
    reading at a time: read together (one set of transforms for a haze pair, through the
    wave models' ``reflected_fractions``) the haze readings moved by 1e-9 between a process
    whose OpenBLAS runs threads and a dask worker whose does not (``tests/test_batch.py``:
    a batch must read the same numbers wherever it runs): the pair's zero-padded DFT-matrix
    product (:func:`goniolab.optics.psd.pruned_fft2`) is large enough for OpenBLAS to
    thread it."""
    tb = E430_B_ANGLE_DEG
    gloss_20 = _reading(model, tb, tb, E430_B_SOURCE, E430_B_SPECULAR_RECEPTOR)
    h_lo = _reading(model, tb, tb - E430_B_HAZE_OFFSET_DEG, E430_B_SOURCE, E430_B_HAZE_RECEPTOR)
    h_hi = _reading(model, tb, tb + E430_B_HAZE_OFFSET_DEG, E430_B_SOURCE, E430_B_HAZE_RECEPTOR)
    ta = E430_A_ANGLE_DEG
    rs = _reading(model, ta, ta, E430_A_SOURCE, E430_A_SPECULAR_RECEPTOR)
    r03 = _reading(model, ta, ta + E430_A_DOI_OFFSET_DEG, E430_A_SOURCE, E430_A_SPECULAR_RECEPTOR)

    def pair(offset: float) -> float:
        lo = _reading(model, ta, ta - offset, E430_A_SOURCE, E430_A_HAZE_RECEPTOR)
        hi = _reading(model, ta, ta + offset, E430_A_SOURCE, E430_A_HAZE_RECEPTOR)
        return 0.5 * (lo + hi)

    doi = 100.0 * (rs - r03) / rs if rs > 0.0 else 0.0
    return E430Report(
        gloss_20=gloss_20,
        haze_18_1=h_lo,
        haze_21_9=h_hi,
        haze_b=0.5 * (h_lo + h_hi),
        gloss_30=rs,
        haze_narrow=pair(E430_A_NARROW_HAZE_OFFSET_DEG),
        haze_wide=pair(E430_A_WIDE_HAZE_OFFSET_DEG),
        doi=doi,
    )


def gloss_report(model: ReflectanceModel) -> GlossReport:
    """Gloss (ISO 2813), haze index (ASTM D4039), E430 haze/DOI and the D523 geometry.

    Parameters
    ----------
    model
        Any reflectance model (facet model of a height map, analytic model).

    Returns
    -------
    GlossReport
        ``G20, G60, G85`` in GU; ``haze_index = G60 - G20``; ``e430`` (:class:`E430Report`);
        ``d523_recommended_angle`` in degrees.
    """
    g = model.gloss((20, 60, 85))
    models, warnings = report_provenance(model)
    return GlossReport(
        G20=g[20],
        G60=g[60],
        G85=g[85],
        haze_index=g[60] - g[20],
        e430=e430_report(model),
        d523_recommended_angle=d523_recommended_angle(g[60]),
        models=models,
        warnings=warnings,
    )


def report_provenance(model: ReflectanceModel) -> tuple[dict[str, str], tuple[str, ...]]:
    """The model that computes each reading of :func:`gloss_report` and the notes
    (:func:`goniolab.optics.provenance.provenance_of`): keys ``G20``, ``G60``, ``G85`` and
    the :class:`E430Report` fields as ``e430.<field>`` (haze and DOI: the off-specular
    receptor's; a mean, the worse of its two)."""
    from goniolab.optics.provenance import gloss_provenance_of, provenance_of

    models: dict[str, str] = {}
    notes: dict[str, None] = {}
    for t, p in gloss_provenance_of(model).items():
        models[f"G{t}"] = p.model
        notes.update(dict.fromkeys(f"G{t}: {n}" for n in p.notes))
    tb, ta = E430_B_ANGLE_DEG, E430_A_ANGLE_DEG
    readings: dict[str, list[tuple[float, float, Rect, Rect]]] = {
        "gloss_20": [(tb, tb, E430_B_SOURCE, E430_B_SPECULAR_RECEPTOR)],
        "haze_18_1": [(tb, tb - E430_B_HAZE_OFFSET_DEG, E430_B_SOURCE, E430_B_HAZE_RECEPTOR)],
        "haze_21_9": [(tb, tb + E430_B_HAZE_OFFSET_DEG, E430_B_SOURCE, E430_B_HAZE_RECEPTOR)],
        "gloss_30": [(ta, ta, E430_A_SOURCE, E430_A_SPECULAR_RECEPTOR)],
        "haze_narrow": [
            (ta, ta + s * E430_A_NARROW_HAZE_OFFSET_DEG, E430_A_SOURCE, E430_A_HAZE_RECEPTOR)
            for s in (-1.0, 1.0)
        ],
        "haze_wide": [
            (ta, ta + s * E430_A_WIDE_HAZE_OFFSET_DEG, E430_A_SOURCE, E430_A_HAZE_RECEPTOR)
            for s in (-1.0, 1.0)
        ],
        "doi": [
            (ta, ta, E430_A_SOURCE, E430_A_SPECULAR_RECEPTOR),
            (ta, ta + E430_A_DOI_OFFSET_DEG, E430_A_SOURCE, E430_A_SPECULAR_RECEPTOR),
        ],
    }
    readings["haze_b"] = readings["haze_18_1"] + readings["haze_21_9"]
    for name, geoms in readings.items():
        provs = [provenance_of(model, *geo) for geo in geoms]
        names = sorted({p.model for p in provs})
        models[f"e430.{name}"] = names[0] if len(names) == 1 else " + ".join(names)
        for p in provs:
            notes.update(dict.fromkeys(f"e430.{name}: {n}" for n in p.notes))
    return models, tuple(notes)
