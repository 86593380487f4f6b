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
:mod:`~goniolab.optics.analytic` and :mod:`~goniolab.optics.fit`.

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
"""

from goniolab.optics.analytic import AnalyticModel
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
from goniolab.optics.fit import FitResult, fit_to_curve, fit_to_gloss
from goniolab.optics.fresnel import fresnel, fresnel_conductor, fresnel_dielectric
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
