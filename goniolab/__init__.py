"""goniolab: goniospectrophotometer and glossmeter control with a roughness-based model.

Predicts the in-plane BRDF and the ISO 2813 gloss of a coating from its measured height map
(Wittmann et al. 2021, Prog. Org. Coat. 156, 106247) and compares the prediction, live,
with measurements from the instruments.
"""

from __future__ import annotations

from goniolab._version import __version__

__all__ = ["__version__"]
