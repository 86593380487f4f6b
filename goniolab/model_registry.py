"""The registry of scattering models: name -> factory, description, validity, height map.

Every place that names a scattering model reads this table: the ``--model`` choices and
help of ``goniolab predict``, ``scan`` and ``fit``, the validation of ``[sample] model`` in
a lab config (:class:`goniolab.config.SampleConfig`), :func:`goniolab.model_cache.model_for`
(which builds the model) and the names a stored run or a result reports. The table is
what :mod:`goniolab.surfaces.registry` is for height-map formats.

This module imports the standard library only: ``goniolab --help`` lists the models
without importing numpy or the optics (tests/test_startup.py). A factory is therefore
named by its dotted path (``"package.module:function"``) and imported the first time a
model of that name is built; a test may register a callable directly.

A factory takes the height map (``None`` for a model that needs none) and the
:class:`ModelOptions`, and returns an object implementing
:class:`goniolab.optics.models.ReflectanceModel`; it raises ``ValueError`` for a map it
cannot model (the caller names the map). Adding a model is one new module (the model and
its factory) plus one :func:`register` call below (docs/ARCHITECTURE.md, "Adding a
scattering model").
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from goniolab.optics.heightmap import HeightMap
    from goniolab.optics.models import ReflectanceModel

__all__ = [
    "DEFAULT_MODEL",
    "Factory",
    "ModelOptions",
    "ScatteringModel",
    "UnknownModel",
    "get",
    "model_help",
    "model_names",
    "register",
    "unregister",
]

#: The model of ``--model`` and ``[sample] model`` when none is given.
DEFAULT_MODEL = "auto"


class UnknownModel(ValueError):
    """A model name that is not registered; the message lists the registered names."""


@dataclass(frozen=True)
class ModelOptions:
    """What every factory is given besides the map (angles in degrees, lengths in um).

    Attributes
    ----------
    n
        Refractive index; complex ``n + ik`` for conductors.
    slope_method, weighting, masking, backend
        Of the facet model (:meth:`goniolab.optics.surface.Surface.from_heightmap`,
        :class:`goniolab.optics.facet.FacetModel`); ``masking`` also of the wave models.
        ``backend`` is that of ``model="facet"``: ``auto`` runs its facet model on the
        slope cells (``"lean"``) whatever it says (:func:`goniolab.model_cache.build_auto`).
    wavelength_nm
        Wavelength of every response of a wave-optics model, or ``None``: 550 nm for
        curves, gloss weighted over CIE C x V(lambda) as ISO 2813 does.
    facet
        The facet model of the same map and options, or a function that builds it on
        first use (a model whose entry has ``uses_facet`` gets the cached one from
        :func:`goniolab.model_cache.model_for`, built only if a geometry needs it).
    """

    n: complex = complex(1.55)
    slope_method: str = "forward"
    weighting: str = "radiometric"
    masking: bool = True
    wavelength_nm: float | None = None
    backend: str = "lean"
    facet: Any = None


#: ``factory(height_map_or_None, options) -> ReflectanceModel``
Factory = Callable[["HeightMap | None", ModelOptions], "ReflectanceModel"]


@dataclass(frozen=True)
class ScatteringModel:
    """One registered scattering model.

    Attributes
    ----------
    name
        The name of ``--model`` and ``[sample] model`` (lower case, no spaces).
    factory
        ``"package.module:function"`` (imported on first use) or the factory itself.
    description
        One line for ``--help`` and the docs.
    validity
        Where the model holds (the regime, with its source), for the docs and ``--help``.
    needs_heightmap
        Whether the factory needs the surface's height map; ``False``: it gets ``None`` and
        the surface spec is not read (a model with parameters of its own).
    uses_facet
        Whether the factory takes the facet model of the map in ``options.facet`` (built
        once and shared, as ``auto`` does to hand geometries over to it).
    """

    name: str
    factory: str | Factory
    description: str
    validity: str
    needs_heightmap: bool = True
    uses_facet: bool = False

    def load(self) -> Factory:
        """The factory (imported now when given by its dotted path)."""
        if not isinstance(self.factory, str):
            return self.factory
        module, _, attr = self.factory.partition(":")
        fn: Factory = getattr(importlib.import_module(module), attr)
        return fn


_MODELS: dict[str, ScatteringModel] = {}


def register(entry: ScatteringModel, *, replace: bool = False) -> ScatteringModel:
    """Add ``entry`` to the table (``replace=True`` to redefine a name); returns it.

    Raises
    ------
    ValueError
        The name is taken (without ``replace``), empty, or has upper case or spaces.
    """
    name = entry.name
    if not name or name != name.strip().lower() or " " in name:
        raise ValueError(f"model name {name!r}: lower case, no spaces")
    if name in _MODELS and not replace:
        raise ValueError(f"model {name!r} is already registered")
    _MODELS[name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove a model (a test's toy model); a name that is not registered is an error."""
    get(name)
    del _MODELS[name]


def model_names() -> tuple[str, ...]:
    """The registered names, in registration order (the default, ``auto``, first)."""
    return tuple(_MODELS)


def get(name: str) -> ScatteringModel:
    """The entry of ``name``.

    Raises
    ------
    UnknownModel
        Naming the model and the registered ones.
    """
    entry = _MODELS.get(name)
    if entry is None:
        raise UnknownModel(f"unknown model {name!r}; use one of {', '.join(_MODELS)}")
    return entry


def model_help() -> str:
    """The ``--model`` help: every model with its description (argparse ``%`` escaped)."""
    parts = [f"{m.name}: {m.description}" for m in _MODELS.values()]
    return ("scattering model (default " + DEFAULT_MODEL + "); " + "; ".join(parts)).replace(
        "%", "%%"
    )


# ---------------------------------------------------------------------- built-in models
register(
    ScatteringModel(
        "auto",
        "goniolab.model_cache:build_auto",
        "per geometry, the model the regime rule picks from Sq/lambda, slope and "
        "correlation length (goniolab.optics.model_choice)",
        "everywhere the chosen model holds; each reading names the model that computed it",
        uses_facet=True,
    )
)
register(
    ScatteringModel(
        "facet",
        "goniolab.model_cache:build_facet",
        "geometric optics: every pixel a Fresnel mirror (Wittmann et al. 2021)",
        "rough surfaces, Rayleigh factor g >= 20 (no coherent beam, no diffraction)",
    )
)
register(
    ScatteringModel(
        "kirchhoff",
        "goniolab.model_cache:build_kirchhoff",
        "scalar Kirchhoff, FFT of the map's phase screen (Beckmann-Spizzichino 1963)",
        "tangent-plane approximation: correlation length above lambda, the map's step "
        "sampling the phase screen (<= 1.2 rad rms per point)",
    )
)
register(
    ScatteringModel(
        "rayleigh-rice",
        "goniolab.model_cache:build_rayleigh_rice",
        "first-order perturbation from the map's PSD (Stover 2012, ch. 5)",
        "smooth surfaces: g <= 0.3 and rms slope Sdq <= 0.3",
    )
)
