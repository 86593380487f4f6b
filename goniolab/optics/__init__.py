"""Pure-numpy optics: BRDF and ISO 2813 gloss predicted from a measured height map.

The chain of Wittmann et al. (2021), with the slips listed in docs/PHYSICS.md
("The seed's slips, in one list") corrected:

height map (:mod:`~goniolab.optics.heightmap`) -> slopes and slope distribution
(:mod:`~goniolab.optics.surface`, seed sec. 3.1) -> facets reflecting with Fresnel
(:mod:`~goniolab.optics.fresnel`, seed eq. 9; :mod:`~goniolab.optics.facet`, seed eqs. 4-8
with the eq. 4 sign and eq. 10 angles fixed and the radiometric facet weight added) ->
integrated over each instrument's aperture (:mod:`~goniolab.optics.apertures`, Mihalik
eqs. 15-17; :mod:`~goniolab.optics.gloss_standards`, ISO 2813 / ASTM D523 / D4039 / E430).
Analytic comparison models (Beckmann, GGX, Cook-Torrance, Ward) and fits to readings are in
:mod:`~goniolab.optics.analytic` and :mod:`~goniolab.optics.analytic_fit`.

No I/O except height-map files, no drivers, no UI: numpy, scipy and numba only.

References
----------
.. [1] B. Wittmann, P. Montmitonnet, A. Burr, C. Gauthier, J.-F. Agassant, A. Casoli,
   "BRDF and gloss computation of polyurethane coatings from roughness measurements:
   modelling and experimental validation", Prog. Org. Coat. 156 (2021) 106247.
.. [2] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer".
.. [3] B. Walter, S. Marschner, H. Li, K. Torrance, "Microfacet models for refraction through
   rough surfaces", EGSR 2007. E. Heitz, "Understanding the masking-shadowing function in
   microfacet-based BRDFs", JCGT 3(2) 2014.

Importing the package is cheap: its names are loaded from their modules on first use
(PEP 562), so ``goniolab.optics.apertures`` does not drag in scipy (``fit``, ``analytic``)
or numba (``facet``) with it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from goniolab.lazy_imports import lazy_exports

# Loaded at once: the function shares its name with its module, and a lazy name would be
# shadowed by the submodule as soon as anything imports goniolab.optics.fresnel.
from goniolab.optics.fresnel import fresnel

if TYPE_CHECKING:
    from goniolab.optics.analytic import AnalyticModel
    from goniolab.optics.analytic_fit import FitResult, fit_to_curve, fit_to_gloss
    from goniolab.optics.apertures import (
        GONIO_CONE,
        ISO2813_BLACK_GLASS_N,
        ISO2813_RECEPTOR,
        ISO2813_SOURCE,
        Aperture,
        Cone,
        Rect,
        integrate_brdf,
    )
    from goniolab.optics.facet import FacetModel, HemisphereBRDF
    from goniolab.optics.fresnel import fresnel_conductor, fresnel_dielectric
    from goniolab.optics.gloss_standards import GlossReport, d523_recommended_angle, gloss_report
    from goniolab.optics.heightmap import (
        HeightMap,
        HeightMapError,
        fill_missing,
        level_plane,
    )
    from goniolab.optics.metrics import PeakMetrics, peak_metrics
    from goniolab.optics.models import ReflectanceModel
    from goniolab.optics.surface import (
        RoughnessStats,
        SlopeHistogram,
        Surface,
        roughness_stats,
        slope_histogram,
        slopes,
    )

_LAZY: dict[str, str] = {
    "AnalyticModel": "goniolab.optics.analytic",
    "Aperture": "goniolab.optics.apertures",
    "Cone": "goniolab.optics.apertures",
    "FacetModel": "goniolab.optics.facet",
    "FitResult": "goniolab.optics.analytic_fit",
    "GONIO_CONE": "goniolab.optics.apertures",
    "GlossReport": "goniolab.optics.gloss_standards",
    "HeightMap": "goniolab.optics.heightmap",
    "HeightMapError": "goniolab.optics.heightmap",
    "HemisphereBRDF": "goniolab.optics.facet",
    "ISO2813_BLACK_GLASS_N": "goniolab.optics.apertures",
    "ISO2813_RECEPTOR": "goniolab.optics.apertures",
    "ISO2813_SOURCE": "goniolab.optics.apertures",
    "PeakMetrics": "goniolab.optics.metrics",
    "Rect": "goniolab.optics.apertures",
    "ReflectanceModel": "goniolab.optics.models",
    "RoughnessStats": "goniolab.optics.surface",
    "SlopeHistogram": "goniolab.optics.surface",
    "Surface": "goniolab.optics.surface",
    "d523_recommended_angle": "goniolab.optics.gloss_standards",
    "fill_missing": "goniolab.optics.heightmap",
    "fit_to_curve": "goniolab.optics.analytic_fit",
    "fit_to_gloss": "goniolab.optics.analytic_fit",
    "fresnel_conductor": "goniolab.optics.fresnel",
    "fresnel_dielectric": "goniolab.optics.fresnel",
    "gloss_report": "goniolab.optics.gloss_standards",
    "integrate_brdf": "goniolab.optics.apertures",
    "level_plane": "goniolab.optics.heightmap",
    "peak_metrics": "goniolab.optics.metrics",
    "roughness_stats": "goniolab.optics.surface",
    "slope_histogram": "goniolab.optics.surface",
    "slopes": "goniolab.optics.surface",
}


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)

__all__ = [
    "GONIO_CONE",
    "ISO2813_BLACK_GLASS_N",
    "ISO2813_RECEPTOR",
    "ISO2813_SOURCE",
    "AnalyticModel",
    "Aperture",
    "Cone",
    "FacetModel",
    "FitResult",
    "GlossReport",
    "HeightMap",
    "HeightMapError",
    "HemisphereBRDF",
    "PeakMetrics",
    "Rect",
    "ReflectanceModel",
    "RoughnessStats",
    "SlopeHistogram",
    "Surface",
    "d523_recommended_angle",
    "fill_missing",
    "fit_to_curve",
    "fit_to_gloss",
    "fresnel",
    "fresnel_conductor",
    "fresnel_dielectric",
    "gloss_report",
    "integrate_brdf",
    "level_plane",
    "peak_metrics",
    "roughness_stats",
    "slope_histogram",
    "slopes",
]
