"""Built-in synthetic samples: deterministic height maps for ``sample:NAME``.

The library (``configs/samples.toml``) holds a flat surface, isotropic Gaussian surfaces of
known rms slope, and analogues of the eight polyurethane coatings of Wittmann et al. (2021,
table 1): a smooth film (long-wavelength Gaussian waviness with sparse micro-defects,
Ra ~ 30 nm) plus spherical-cap filler bumps of the listed sizes and loadings, and a rough
special-cure surface (#8).

Every map is generated from a seed with numpy's PCG64 generator, vectorised (an FFT filter
for the random fields, one ``bincount`` per filler population for the caps; periodic
boundaries) and cached, so ``make_sample`` returns the same read-only map every time.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, table 1 and sec. 3.1.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from labtoml import TomlFileError, read_toml

if TYPE_CHECKING:  # numpy loads when a map is generated: listing the library needs none
    import numpy as np
    from numpy.typing import NDArray

    from goniolab.optics.heightmap import HeightMap

    FloatArray = NDArray[np.float64]

__all__ = [
    "SAMPLES_TOML",
    "SampleError",
    "SampleInfo",
    "make_sample",
    "sample_info",
    "sample_names",
]


_REPO_CONFIG = Path(__file__).resolve().parents[2] / "configs" / "samples.toml"
_WHEEL_CONFIG = Path(__file__).resolve().parents[1] / "_configs" / "samples.toml"
#: The sample library: the repository's ``configs/samples.toml`` (or the wheel's copy).
SAMPLES_TOML: Path = _REPO_CONFIG if _REPO_CONFIG.exists() else _WHEEL_CONFIG

_KINDS = ("flat", "gaussian", "coating", "rough")


class SampleError(ValueError):
    """A sample name that does not exist or a malformed sample definition (names the key)."""


@dataclass(frozen=True)
class SampleInfo:
    """One built-in sample as described in ``configs/samples.toml``.

    ``seed_ra_nm`` and ``seed_g60`` are the seed paper's measured values (Wittmann table 1)
    for the coating analogues, ``None`` for the other samples.
    """

    name: str
    kind: str
    description: str
    n: complex
    seed_ra_nm: float | None
    seed_g60: float | None
    params: Mapping[str, Any]


@dataclass(frozen=True)
class _Library:
    size: int
    step_um: float
    seed: int
    samples: dict[str, SampleInfo]


def _num(table: Mapping[str, Any], key: str, where: str, *, default: float | None = None) -> float:
    if key not in table:
        if default is not None:
            return default
        raise SampleError(f"{SAMPLES_TOML}: {where}.{key} is missing")
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SampleError(f"{SAMPLES_TOML}: {where}.{key} must be a finite number, got {value!r}")
    return float(value)


def _check_params(info: SampleInfo, where: str) -> None:
    p = info.params
    # the paint table is checked where it is built (goniolab.model_cache.paint_for: one error
    # naming samples.NAME.paint.KEY); here only its shape, so `goniolab samples` stays light
    if "paint" in p and not isinstance(p["paint"], Mapping):
        raise SampleError(f"{SAMPLES_TOML}: {where}.paint must be a table")
    if info.kind == "gaussian":
        for key in ("slope_rms", "corr_length_um"):
            if _num(p, key, where) <= 0:
                raise SampleError(f"{SAMPLES_TOML}: {where}.{key} must be > 0")
    elif info.kind == "rough":
        for key in ("ra_nm", "corr_length_um"):
            if _num(p, key, where) <= 0:
                raise SampleError(f"{SAMPLES_TOML}: {where}.{key} must be > 0")
    elif info.kind == "coating":
        for key in ("film_ra_nm", "film_corr_um"):
            if _num(p, key, where) < 0:
                raise SampleError(f"{SAMPLES_TOML}: {where}.{key} must be >= 0")
        fillers = p.get("fillers", [])
        if not isinstance(fillers, list):
            raise SampleError(f"{SAMPLES_TOML}: {where}.fillers must be an array of tables")
        entries = [(f"{where}.fillers[{i}]", f) for i, f in enumerate(fillers)]
        if "film_defects" in p:
            entries.append((f"{where}.film_defects", p["film_defects"]))
        for fw, f in entries:
            if not isinstance(f, Mapping):
                raise SampleError(f"{SAMPLES_TOML}: {fw} must be a table")
            d = f.get("diameter_um")
            ok = (
                isinstance(d, list)
                and len(d) == 2
                and all(isinstance(x, int | float) and x > 0 for x in d)
                and d[0] <= d[1]
            )
            if not ok:
                raise SampleError(
                    f"{SAMPLES_TOML}: {fw}.diameter_um must be [min, max] > 0, got {d!r}"
                )
            for key in ("area_fraction", "cap_height_um"):
                if _num(f, key, fw) <= 0:
                    raise SampleError(f"{SAMPLES_TOML}: {fw}.{key} must be > 0")


@functools.cache
def _library() -> _Library:
    try:
        data = read_toml(SAMPLES_TOML, what="sample library")
    except TomlFileError as exc:
        raise SampleError(str(exc)) from None
    defaults = data.get("defaults", {})
    size = int(_num(defaults, "size", "defaults", default=512))
    step = _num(defaults, "step_um", "defaults", default=1.0)
    seed = int(_num(defaults, "seed", "defaults", default=1))
    samples: dict[str, SampleInfo] = {}
    for name, table in data.get("samples", {}).items():
        where = f"samples.{name}"
        kind = table.get("kind")
        if kind not in _KINDS:
            raise SampleError(
                f"{SAMPLES_TOML}: {where}.kind must be one of {', '.join(_KINDS)}, got {kind!r}"
            )
        n = complex(_num(table, "n", where), _num(table, "k", where, default=0.0))
        ra = table.get("seed_ra_nm")
        g60 = table.get("seed_g60")
        info = SampleInfo(
            name=name,
            kind=kind,
            description=str(table.get("description", "")),
            n=n,
            seed_ra_nm=None if ra is None else _num(table, "seed_ra_nm", where),
            seed_g60=None if g60 is None else _num(table, "seed_g60", where),
            params=dict(table),
        )
        _check_params(info, where)
        samples[name] = info
    return _Library(size=size, step_um=step, seed=seed, samples=samples)


def sample_names() -> list[str]:
    """Names of the built-in samples, in library order."""
    return list(_library().samples)


def sample_info(name: str) -> SampleInfo:
    """The library entry of a sample; unknown names raise :class:`SampleError` listing them."""
    lib = _library()
    try:
        return lib.samples[name]
    except KeyError:
        import difflib

        close = difflib.get_close_matches(name, list(lib.samples), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise SampleError(
            f"unknown sample {name!r}{hint}; known samples: {', '.join(lib.samples)}"
        ) from None


# --------------------------------------------------------------------------------------
# Generators
# --------------------------------------------------------------------------------------


def _gaussian_field(
    rng: np.random.Generator, shape: tuple[int, int], step_um: float, corr_um: float
) -> FloatArray:
    """Zero-mean, unit-variance periodic random field with ACF exp(-r^2 / L^2).

    White noise filtered in Fourier space by sqrt(PSD) = exp(-k^2 L^2 / 8), the square root of
    the PSD of that ACF (Wiener-Khinchin), then normalised to unit variance.
    """
    import numpy as np

    ny, nx = shape
    noise = rng.standard_normal(shape)
    ky = 2.0 * np.pi * np.fft.fftfreq(ny, d=step_um)
    kx = 2.0 * np.pi * np.fft.rfftfreq(nx, d=step_um)
    k2 = ky[:, None] ** 2 + kx[None, :] ** 2
    field = np.fft.irfft2(np.fft.rfft2(noise) * np.exp(-k2 * corr_um**2 / 8.0), s=shape)
    field -= field.mean()
    sd = field.std()
    return np.asarray(field / sd if sd > 0 else field)


def _rms_forward_slope(z: FloatArray, step_um: float) -> float:
    """Mean of the per-axis rms forward-difference slopes (periodic)."""
    import numpy as np

    sx = np.sqrt(np.mean((np.roll(z, -1, axis=1) - z) ** 2)) / step_um
    sy = np.sqrt(np.mean((np.roll(z, -1, axis=0) - z) ** 2)) / step_um
    return float(0.5 * (sx + sy))


def _ra(z: FloatArray) -> float:
    import numpy as np

    return float(np.mean(np.abs(z - z.mean())))


def _caps(
    rng: np.random.Generator,
    shape: tuple[int, int],
    step_um: float,
    diameter_um: tuple[float, float],
    area_fraction: float,
    cap_height_um: float,
) -> FloatArray:
    """Sum of spherical caps of base diameter d in [d_min, d_max] and height h at random centres.

    A cap of base radius a and height h is part of a sphere of radius R = (a^2 + h^2) / (2h):
    z(r) = sqrt(R^2 - r^2) - (R - h) for r < a. The number of caps is
    area_fraction * area / (pi <a^2>); overlapping caps add (filler piling up).
    """
    import numpy as np

    ny, nx = shape
    d_min, d_max = diameter_um
    a_mean_sq = (d_min**2 + d_min * d_max + d_max**2) / 12.0  # <(d/2)^2>, d uniform
    count = round(float(area_fraction * nx * ny * step_um**2 / (math.pi * a_mean_sq)))
    z = np.zeros(ny * nx)
    if count == 0:
        return np.zeros(shape)
    a = 0.5 * rng.uniform(d_min, d_max, size=count)
    cx = rng.uniform(0.0, nx, size=count)
    cy = rng.uniform(0.0, ny, size=count)
    radius_px = np.ceil(a / step_um).astype(np.int64)
    for rp in np.unique(radius_px):
        sel = radius_px == rp
        off = np.arange(-rp, rp + 1)
        grid_y, grid_x = np.meshgrid(off, off, indexing="ij")
        oy, ox = grid_y.ravel(), grid_x.ravel()
        iy = np.floor(cy[sel])[:, None].astype(np.int64) + oy[None, :]
        ix = np.floor(cx[sel])[:, None].astype(np.int64) + ox[None, :]
        # Distance from each cap centre to the pixel centres (i + 1/2) in micrometres.
        ry = (iy + 0.5 - cy[sel][:, None]) * step_um
        rx = (ix + 0.5 - cx[sel][:, None]) * step_um
        r2 = rx**2 + ry**2
        ai = a[sel][:, None]
        big_r = (ai**2 + cap_height_um**2) / (2.0 * cap_height_um)
        h = np.sqrt(np.clip(big_r**2 - r2, 0.0, None)) - (big_r - cap_height_um)
        h = np.where(r2 < ai**2, np.clip(h, 0.0, None), 0.0)
        flat = (iy % ny) * nx + (ix % nx)
        z += np.bincount(flat.ravel(), weights=h.ravel(), minlength=ny * nx)
    return np.asarray(z.reshape(shape))


def _generate(info: SampleInfo, shape: tuple[int, int], step_um: float, seed: int) -> FloatArray:
    import numpy as np

    p = info.params
    # One independent stream per (seed, sample) so samples do not share noise.
    key = [int(b) for b in info.name.encode()]
    rng = np.random.default_rng([seed, *key])
    if info.kind == "flat":
        return np.zeros(shape)
    if info.kind == "gaussian":
        z = _gaussian_field(rng, shape, step_um, float(p["corr_length_um"]))
        return z * (float(p["slope_rms"]) / _rms_forward_slope(z, step_um))
    if info.kind == "rough":
        z = _gaussian_field(rng, shape, step_um, float(p["corr_length_um"]))
        return z * (float(p["ra_nm"]) * 1e-3 / _ra(z))
    film = _gaussian_field(rng, shape, step_um, float(p["film_corr_um"]))
    film_ra = _ra(film)
    z = film * (float(p["film_ra_nm"]) * 1e-3 / film_ra) if film_ra > 0 else film
    populations = list(p.get("fillers", []))
    if "film_defects" in p:
        populations.insert(0, p["film_defects"])
    for f in populations:
        d = f["diameter_um"]
        z = z + _caps(
            rng,
            shape,
            step_um,
            (float(d[0]), float(d[1])),
            float(f["area_fraction"]),
            float(f["cap_height_um"]),
        )
    return np.asarray(z - z.mean())


@functools.lru_cache(maxsize=32)
def _make_cached(name: str, shape: tuple[int, int], step_um: float, seed: int) -> HeightMap:
    from goniolab.optics.heightmap import HeightMap

    info = sample_info(name)
    z = _generate(info, shape, step_um, seed)
    meta = {
        "sample": name,
        "description": info.description,
        "n": str(info.n.real) if info.n.imag == 0 else str(info.n),
        "seed": str(seed),
        # a stored tag (sim/truth.py reads it), kept from when this module was surfaces/samples.py
        "generator": "goniolab.surfaces.samples",
    }
    return HeightMap(z_um=z, dx_um=step_um, dy_um=step_um, source=f"sample:{name}", meta=meta)


def make_sample(
    name: str,
    *,
    size: int | tuple[int, int] | None = None,
    seed: int | None = None,
    step_um: float | None = None,
) -> HeightMap:
    """Generate (or fetch from the cache) the height map of a built-in sample.

    Parameters
    ----------
    name
        A name from :func:`sample_names` (``flat``, ``gaussian-s0.05``, ``wittmann-3`` ...).
    size
        Points per side, or ``(ny, nx)``; default from ``[defaults] size`` (512).
    seed
        Random seed; default ``[defaults] seed``. Same arguments, same map.
    step_um
        Lateral step in micrometres; default ``[defaults] step_um`` (1 um). Features keep their
        physical size (um), so a larger step covers a larger area more coarsely.

    Returns
    -------
    HeightMap
        Heights in micrometres (zero mean), ``source = "sample:NAME"``; read-only and shared
        between callers (cached).

    Raises
    ------
    SampleError
        Unknown name (the message lists the known ones) or bad size/step.
    """
    lib = _library()
    sample_info(name)
    if size is None:
        shape = (lib.size, lib.size)
    elif isinstance(size, int):
        shape = (size, size)
    else:
        shape = (int(size[0]), int(size[1]))
    if min(shape) < 2:
        raise SampleError(f"sample {name!r}: size must be at least 2 x 2, got {shape}")
    step = lib.step_um if step_um is None else float(step_um)
    if not (math.isfinite(step) and step > 0):
        raise SampleError(f"sample {name!r}: step_um must be finite and > 0, got {step_um!r}")
    return _make_cached(name, shape, step, lib.seed if seed is None else int(seed))
