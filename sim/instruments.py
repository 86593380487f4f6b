"""The simulated lab in-process: arms, spectro-colorimeter and glossmeter.

Each class implements the matching :mod:`drivers.base` Protocol, so the scan runner, the
CLI and the contract tests use them exactly like the real drivers. The simulated
goniometer is the project's own ``drivers.goniometer.TwoArmGoniometer(SimAxis, SimAxis)``
(built by :mod:`goniolab.lab_wiring`, since :mod:`sim` imports only ``drivers.base``,
``drivers.profiles`` and ``goniolab.optics``): one interlock for real and simulated arms. Readings come from
the physics: a :class:`goniolab.optics.models.ReflectanceModel` (normally the
``FacetModel`` of the sample's height map) evaluated at the geometry the arms *really*
have -- including the sample tilt and the arms' zero offsets that Wittmann et al. (2021,
sec. 5.2-5.3) name as the cause of the scatter on glossy samples -- through the
configured source and detector cones. Model evaluation is CPU work and runs in a thread
(:func:`asyncio.to_thread`) so the event loop never stalls.

Two twins (config ``[sim.twin] mode``, :mod:`goniolab.lab_wiring`):

* **ideal**: the spectro and glossmeter read the prediction's own model, with a relative
  noise ``noise_pct``; nothing else (tests of the plumbing compare exactly).
* **realistic**: they read the sample's hidden truth (:mod:`sim.truth`) through a
  :class:`SpectroChain` (lamp spectrum x detector response, dark current and shot noise
  growing with the exposure, read noise, a 16-bit full scale that saturates, a stray-light
  floor, lamp flicker) and a glossmeter with :class:`GlossDrift` (calibration drift and
  warm-up temperature); the arms have backlash (:class:`SimAxis`), and zero offsets and a
  sample tilt drawn per session (:func:`sim.assembly.build_sim_instruments`).

Each instrument is a room of its own: :mod:`sim.twin_axis` (:class:`SimAxis`),
:mod:`sim.twin_spectro` (:class:`SimSpectro`, :class:`MirrorModel`,
:func:`effective_angles`), :mod:`sim.spectro_chain` (:class:`SpectroChain`, the lamp and
detector spectra), :mod:`sim.twin_gloss` (:class:`SimGlossmeter`, :class:`GlossDrift`), on
the shared link of :mod:`sim.twin_link`; this module gathers their public names.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 2.3 (instrument),
   sec. 5.2-5.3 (misalignment).
.. [2] ISO 2813:2014 / ASTM D523: specular gloss at 20/60/85 deg.
.. [3] Zehntner ZGM1120 Technical Manual rev. 3.0 (2021), pp. 16-28: 0.1 GU resolution,
   -2 = overflow.
"""

from __future__ import annotations

from sim.spectro_chain import (
    SpectroChain,
    detector_response,
    lamp_spectrum,
    spectrum_for_luminance,
)
from sim.twin_axis import SimAxis
from sim.twin_gloss import GLOSS_OVERFLOW_GU, GlossDrift, SimGlossmeter
from sim.twin_spectra import SPECTRUM_WAVELENGTHS_NM
from sim.twin_spectro import LuminanceModel, MirrorModel, SimSpectro, effective_angles

__all__ = [
    "GLOSS_OVERFLOW_GU",
    "SPECTRUM_WAVELENGTHS_NM",
    "GlossDrift",
    "LuminanceModel",
    "MirrorModel",
    "SimAxis",
    "SimGlossmeter",
    "SimSpectro",
    "SpectroChain",
    "detector_response",
    "effective_angles",
    "lamp_spectrum",
    "spectrum_for_luminance",
]
