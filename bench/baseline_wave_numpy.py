"""Plain-numpy baseline of the wave models: what a numpy user writes for the same physics.

Run:  python bench/baseline_wave_numpy.py MAP.npy brdf|gloss [--model auto|kirchhoff|rayleigh-rice]

The companion of ``bench/baseline_numpy.py`` (the facet model) for the maps where
``goniolab``'s ``auto`` picks a wave model (issue 26: "<= 0.5 x, paired against
bench/baseline_numpy.py (or an equivalent plain numpy script)"). It computes what
docs/PHYSICS.md and ``goniolab/optics/kirchhoff.py`` / ``rayleigh_rice.py`` state, the
way a numpy user writes it from those formulas, without goniolab:

- reads the ``.npy`` map (step from the ``.npy.json`` sidecar, else 1 um), levels it by the
  least-squares plane (as ``baseline_numpy.py``), cuts it into equal tiles of at most 1024
  points per side, each times the Schwartz window of taper 0.25 (PHYSICS.md / the NIST
  seed), the window-weighted mean removed: the tiles goniolab transforms, so that the
  speckle of the two is the same (a single 2048^2 transform would be other speckle);
- **Kirchhoff** (scalar, tangent plane): per reading, ``v_z = k (cos ti + cos tr)`` at the
  receptor's centre and per tile the transform ``U = fft2(W exp(-i v_z h))`` with
  ``numpy.fft`` (float64 / complex128, as a float64 map gives), zero-padded when the
  receptor is narrower than 6 cells (PHYSICS.md, "No silent fallback"; goniolab's rule);
  a cell's diffuse flux fraction is ``R(wi.h) |G|^2 mean_tiles |U_d|^2 / (N sum W^2)``
  (Beckmann's obliquity ``|G|^2 = |wi + wo|^4 / (4 cos ti cos to (cos ti + cos to)^2)``,
  Fresnel at the half vector), its direction from the grating equation ``(wi + wo)_xy =
  lambda m / field``, with ``U_d = U - <W exp(-i v_z h)> fft2(W)``: the coherent field
  taken out, as kirchhoff.py states (the lit spot is far larger than the map, so the
  window's diffraction of it is not light the instrument sees). The coherent beam
  ``R(ti) mean_tiles |<W exp(-i v_spec h)>|^2`` reaches the receptor through the overlap
  of the source image centred at specular;
- **Rayleigh-Rice** (where the regime rule of PHYSICS.md picks it: ``g <= 0.15`` and
  ``Sdq <= 0.15``): the PSD of the windowed tiles (one transform per tile, padded alike),
  a cell's flux ``exp(-g) 16 pi^2 cos ti cos ts Q PSD df_x df_y / lambda^2`` with Stover's
  unpolarised polarisation factor Q, plus the coherent beam ``R(ti) exp(-g)`` at specular;
- **apertures**: ``brdf``: 71 detector positions 0..70 deg at theta_i 45 with 6 deg source
  and detector cones (each cell weighted by the planar lens overlap of the source image
  and the detector, as ``baseline_numpy.py``); ``gloss``: ISO 2813 G20/G60/G85 (source
  0.75 x 2.5 deg, receptors 1.8 x 3.6, 4.4 x 11.7, 4.0 x 6.0 deg) weighted over 16
  wavelengths 400-700 nm by CIE illuminant C x V(lambda) (goniolab's table, CIE 015),
  one transform per wavelength, and the E430 readings at 550 nm (the same receptors as
  ``baseline_numpy.py``), each over the black glass's Fresnel reflectance (n = 1.567).

It prints one JSON object: ``luminance_pct`` (brdf) or the gloss readings, under the keys
of ``goniolab predict ... --json``, and the model of each. ``--model`` forces one model
(default ``auto``: the regime rule at 550 nm). One transform per detector position and
wavelength is the natural plain script: ``v_z`` differs for every reading; goniolab's
Taylor expansion in ``v_z`` (a few transforms serve every cell of a curve) is what a
library adds.

Not computed (so not the reference for accuracy, as ``baseline_numpy.py`` is not): the
Smith masking goniolab weighs into Kirchhoff's diffuse part (``G2^(1 - exp(-g_d))``: on the
bench maps, rms slope 0.05, it changes no reading by more than 1e-4 of it), the energy
check from 70 deg, ``v_z`` across a receptor (fixed at its centre), the coherent beam's own
source integral, and the hand-overs of goniolab's rule to the facet model (a cone beyond the
map's Nyquist window reads only the light the map resolves here). ``bench/bench_lean.py
--check`` compares it with goniolab on the bench maps and states the agreement.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

TILE = 1024
TAPER = 0.25
CELLS_ACROSS = 6
LAMS = np.arange(400.0, 701.0, 20.0)  # nm
CIE_C = np.array([63.3, 98.1, 121.5, 123.1, 123.9, 112.1, 96.9, 102.1,
                  105.3, 97.8, 89.7, 88.1, 87.8, 87.9, 84.0, 76.3])  # fmt: skip
CIE_V = np.array([0.000396, 0.004, 0.023, 0.06, 0.13902, 0.323, 0.71, 0.954,
                  0.995, 0.87, 0.631, 0.381, 0.175, 0.061, 0.017, 0.004102])  # fmt: skip
N_COAT, N_GLASS = 1.55, 1.567
ISO_SOURCE = (0.75, 2.5)
ISO = {20: (1.8, 3.6), 60: (4.4, 11.7), 85: (4.0, 6.0)}  # receptors (in plane, perp), deg
E430 = {  # name: (theta_i, theta_r, source, receptor), deg
    "gloss_20": (20.0, 20.0, (0.75, 2.5), (1.8, 3.6)),
    "haze_18_1": (20.0, 18.1, (0.75, 2.5), (0.4, 3.6)),
    "haze_21_9": (20.0, 21.9, (0.75, 2.5), (0.4, 3.6)),
    "gloss_30": (30.0, 30.0, (0.05, 2.5), (0.14, 2.5)),
    "r_30_3": (30.0, 30.3, (0.05, 2.5), (0.14, 2.5)),
    "haze_28": (30.0, 28.0, (0.05, 2.5), (0.4, 2.5)),
    "haze_32": (30.0, 32.0, (0.05, 2.5), (0.4, 2.5)),
    "haze_25": (30.0, 25.0, (0.05, 2.5), (0.4, 2.5)),
    "haze_35": (30.0, 35.0, (0.05, 2.5), (0.4, 2.5)),
}


def load(path: str) -> tuple[np.ndarray, float, float]:
    z = np.load(path)
    side = Path(path + ".json")
    dx = dy = 1.0
    if side.exists():
        info = json.loads(side.read_text())
        dx, dy = float(info["dx_um"]), float(info["dy_um"])
    return z, dx, dy


def level(z: np.ndarray, dx: float, dy: float) -> np.ndarray:
    ny, nx = z.shape
    x = (np.arange(nx) - (nx - 1) / 2.0) * dx
    y = (np.arange(ny) - (ny - 1) / 2.0) * dy
    b = float(z.sum(axis=0) @ x) / (ny * float(x @ x))
    c = float(z.sum(axis=1) @ y) / (nx * float(y @ y))
    return z - z.mean() - b * x[None, :] - c * y[:, None]


def schwartz(n: int) -> np.ndarray:
    x = (np.arange(n) + 0.5) / n
    t = np.clip(np.minimum(x, 1.0 - x) / TAPER, 0.0, 1.0)
    with np.errstate(divide="ignore"):
        a = np.where(t > 0, np.exp(-1.0 / t), 0.0)
        b = np.where(t < 1, np.exp(-1.0 / (1.0 - t)), 0.0)
    return np.where(t >= 1.0, 1.0, a / (a + b))


def tiles(h: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    ny, nx = h.shape
    sy, sx = ny // math.ceil(ny / TILE), nx // math.ceil(nx / TILE)
    w = schwartz(sy)[:, None] * schwartz(sx)[None, :]
    out = []
    for y0 in range(0, sy * (ny // sy), sy):
        for x0 in range(0, sx * (nx // sx), sx):
            t = h[y0 : y0 + sy, x0 : x0 + sx]
            out.append(t - np.sum(w * t) / np.sum(w))
    return out, w


def fresnel(c: np.ndarray, n: float) -> np.ndarray:
    ct = np.sqrt(np.maximum(1.0 - (1.0 - c * c) / (n * n), 0.0))
    rs = (c - n * ct) / (c + n * ct)
    rp = (n * c - ct) / (n * c + ct)
    return 0.5 * (rs * rs + rp * rp)


def q_factor(ti: float, ts: np.ndarray, phi: np.ndarray, n: float) -> np.ndarray:
    """Stover's unpolarised Rayleigh-Rice factor Q (phi from the forward direction)."""
    eps = n * n
    si, ci = math.sin(ti), math.cos(ti)
    ss, cs, cp, sp = np.sin(ts), np.cos(ts), np.cos(phi), np.sin(phi)
    a_i, a_s = math.sqrt(eps - si * si), np.sqrt(eps - ss * ss)
    e1 = eps - 1.0
    q_ss = e1 * cp / ((ci + a_i) * (cs + a_s))
    q_pp = e1 * (eps * si * ss - a_s * a_i * cp) / ((eps * ci + a_i) * (eps * cs + a_s))
    q_ps = -e1 * a_i * sp / ((eps * ci + a_i) * (cs + a_s))
    q_sp = -e1 * a_s * sp / ((ci + a_i) * (eps * cs + a_s))
    return 0.5 * (q_ss**2 + q_pp**2 + q_ps**2 + q_sp**2)


class Map:
    def __init__(self, path: str) -> None:
        z, self.dx, self.dy = load(path)
        h = level(z, self.dx, self.dy)
        self.sq = float(h.std())
        p = np.diff(h, axis=1) / self.dx
        q = np.diff(h, axis=0) / self.dy
        self.sdq = math.sqrt(float(np.mean(p * p)) + float(np.mean(q * q)))
        self.tiles, self.w = tiles(h)
        self.ny, self.nx = self.w.shape
        self.sum_w2 = float(np.sum(self.w**2))
        self.psds: dict[tuple[int, int], np.ndarray] = {}
        self.w_hat: dict[tuple[int, int], np.ndarray] = {}
        self.factors: dict[tuple[float, float, tuple[int, int]], np.ndarray] = {}

    def model(self, ti_deg: float, forced: str) -> str:
        """PHYSICS.md's regime rule at 550 nm: Rayleigh-Rice when g <= 0.15 and Sdq <= 0.15."""
        if forced != "auto":
            return forced
        g = (4 * math.pi * self.sq * math.cos(math.radians(ti_deg)) / 0.55) ** 2
        return "rayleigh-rice" if g <= 0.15 and self.sdq <= 0.15 else "kirchhoff"

    def padding(self, lam: float, rec: tuple[float, float], tr_deg: float) -> tuple[int, int]:
        """Zero padding (y, x) that puts CELLS_ACROSS cells across the receptor."""
        w_in, w_perp = math.radians(rec[0]), math.radians(rec[1])
        w_x = w_in * math.cos(min(abs(math.radians(tr_deg)) + 0.5 * w_in, 0.5 * math.pi))
        os_x = max(1, math.ceil(CELLS_ACROSS * lam / (self.nx * self.dx) / w_x))
        os_y = max(1, math.ceil(CELLS_ACROSS * lam / (self.ny * self.dy) / w_perp))
        return os_y, os_x

    def cells(self, ti: float, lam: float, os: tuple[int, int]):
        """Directions of the (padded) FFT cells: wo_x, wo_y, wo_z and the real ones."""
        ly, lx = os[0] * self.ny, os[1] * self.nx
        wox = np.fft.fftfreq(lx, self.dx / lam)[None, :] - math.sin(ti)
        woy = np.fft.fftfreq(ly, self.dy / lam)[:, None]
        z2 = 1.0 - wox**2 - woy**2
        ok = z2 > 1e-12
        return wox, woy, np.sqrt(np.where(ok, z2, 0.0)), ok

    def kirchhoff(self, ti: float, tr: float, lam: float, os: tuple[int, int]) -> np.ndarray:
        """Diffuse flux fraction per cell, v_z at the receptor's centre: the field minus the
        tile's mean field times the window's transform (the coherent beam, summed apart)."""
        vz = 2 * math.pi / lam * (math.cos(ti) + math.cos(tr))
        ly, lx = os[0] * self.ny, os[1] * self.nx
        if os not in self.w_hat:
            self.w_hat[os] = np.fft.fft2(self.w, s=(ly, lx))
        power = np.zeros((ly, lx))
        for t in self.tiles:
            e = self.w * np.exp(-1j * vz * t)
            u = np.fft.fft2(e, s=(ly, lx)) - (e.sum() / self.w.sum()) * self.w_hat[os]
            power += u.real**2 + u.imag**2
        power /= len(self.tiles) * self.ny * self.nx * self.sum_w2 * os[0] * os[1]
        return power * self.factor(ti, lam, os)

    def coherent(self, ti: float, lam: float, model: str) -> float:
        """Reflectance of the coherent specular beam: R(ti) |<W exp(-i v_z h)>|^2 (Kirchhoff,
        at the specular v_z) or R(ti) exp(-g) (Rayleigh-Rice, g from the PSD's Sq)."""
        r = float(fresnel(np.array(math.cos(ti)), N_COAT))
        if model == "rayleigh-rice":
            sq = math.sqrt(
                float(np.sum(self.psd((1, 1)))) / (self.nx * self.dx * self.ny * self.dy)
            )
            return r * math.exp(-((4 * math.pi * sq * math.cos(ti) / lam) ** 2))
        v = 2 * math.pi / lam * 2 * math.cos(ti)
        c = [abs(np.sum(self.w * np.exp(-1j * v * t)) / self.w.sum()) ** 2 for t in self.tiles]
        return r * float(np.mean(c))

    def factor(self, ti: float, lam: float, os: tuple[int, int]) -> np.ndarray:
        """``R(wi.h) |G|^2`` of every cell (0 for evanescent ones), formed once per grid."""
        key = (ti, lam, os)
        if key not in self.factors:
            wox, woy, woz, ok = self.cells(ti, lam, os)
            ci, si = math.cos(ti), math.sin(ti)
            s2 = (wox + si) ** 2 + woy**2 + (woz + ci) ** 2
            co = np.where(ok, woz, 1.0)
            g2 = s2 * s2 / (4 * ci * co * (ci + co) ** 2)
            r = fresnel(np.clip(0.5 * np.sqrt(s2), 0.0, 1.0), N_COAT)
            self.factors[key] = np.where(ok, r * g2, 0.0)
        return self.factors[key]

    def psd(self, os: tuple[int, int]) -> np.ndarray:
        if os not in self.psds:
            ly, lx = os[0] * self.ny, os[1] * self.nx
            acc = np.zeros((ly, lx))
            for t in self.tiles:
                u = np.fft.fft2(self.w * t, s=(ly, lx))
                acc += u.real**2 + u.imag**2
            self.psds[os] = acc * self.dx * self.dy / (self.sum_w2 * len(self.tiles))
        return self.psds[os]

    def rayleigh_rice(self, ti: float, lam: float, os: tuple[int, int]) -> np.ndarray:
        """Diffuse flux fraction per cell: exp(-g) times the first-order BRDF times the
        cell's area in direction cosines."""
        dw = self.coherent(ti, lam, "rayleigh-rice") / float(
            fresnel(np.array(math.cos(ti)), N_COAT)
        )
        wox, woy, woz, ok = self.cells(ti, lam, os)
        st = np.sqrt(wox**2 + woy**2)
        ts = np.arctan2(st, woz)
        phi = np.where(st > 0, np.arctan2(-woy, -wox), 0.0)
        df2 = 1.0 / (os[1] * self.nx * self.dx * os[0] * self.ny * self.dy)
        q = q_factor(ti, ts, phi, N_COAT)
        p = 16 * math.pi**2 * math.cos(ti) * woz * q * self.psd(os) * df2 / lam**2
        return np.where(ok, dw * p, 0.0)

    def angles(self, ti: float, lam: float, os: tuple[int, int]):
        """In-plane angle (> 0 on the specular side) and out-of-plane angle of the cells."""
        wox, woy, woz, ok = self.cells(ti, lam, os)
        beta = np.broadcast_to(np.arcsin(np.clip(woy, -1, 1)), woz.shape)
        return np.arctan2(-wox, woz), beta, ok


def overlap(x: np.ndarray, s: float, r: float) -> np.ndarray:
    lo = np.maximum(x - 0.5 * s, -0.5 * r)
    hi = np.minimum(x + 0.5 * s, 0.5 * r)
    return np.maximum(hi - lo, 0.0) / s


def lens(g: np.ndarray, r: float) -> np.ndarray:
    """Planar overlap of two circles of radius r at distance g, over pi r^2."""
    gc = np.minimum(g, 2 * r)
    area = 2 * r * r * np.arccos(gc / (2 * r)) - 0.5 * gc * np.sqrt(4 * r * r - gc * gc)
    return area / (math.pi * r * r)


def reading(m: Map, model: str, ti_deg: float, tr_deg: float, src, rec, lam_um: float, os):
    """Flux fraction from the rectangle ``src`` into ``rec`` (deg) at one wavelength."""
    ti, tr = math.radians(ti_deg), math.radians(tr_deg)
    s_in, s_pe = (math.radians(v) for v in src)
    r_in, r_pe = (math.radians(v) for v in rec)
    alpha, beta, ok = m.angles(ti, lam_um, os)
    weight = np.where(ok, overlap(alpha - tr, s_in, r_in) * overlap(beta, s_pe, r_pe), 0.0)
    if model == "kirchhoff":
        diffuse = m.kirchhoff(ti, tr, lam_um, os)
    else:
        diffuse = m.rayleigh_rice(ti, lam_um, os)
    beam = m.coherent(ti, lam_um, model) * float(overlap(np.array(ti - tr), s_in, r_in))
    return float(np.sum(diffuse * weight)) + beam * min(1.0, r_pe / s_pe)


def gloss(m: Map, forced: str) -> dict[str, object]:
    w = CIE_C * CIE_V
    w /= w.sum()
    out: dict[str, object] = {}
    models: dict[str, str] = {}
    for t, rec in ISO.items():
        model = m.model(t, forced)
        os = m.padding(LAMS.max() * 1e-3, rec, t)
        flux = [reading(m, model, t, t, ISO_SOURCE, rec, lam * 1e-3, os) for lam in LAMS]
        ref = float(fresnel(np.array(math.cos(math.radians(t))), N_GLASS))
        out[f"G{t}"] = 100.0 * float(np.dot(w, flux)) / ref
        models[f"G{t}"] = model
    e: dict[str, float] = {}
    for name, (ti, tr, src, rec) in E430.items():
        model = m.model(ti, forced)
        os = m.padding(0.55, rec, tr)
        ref = float(fresnel(np.array(math.cos(math.radians(ti))), N_GLASS))
        e[name] = 100.0 * reading(m, model, ti, tr, src, rec, 0.55, os) / ref
    out["e430"] = {
        "gloss_20": e["gloss_20"],
        "haze_18_1": e["haze_18_1"],
        "haze_21_9": e["haze_21_9"],
        "haze_b": 0.5 * (e["haze_18_1"] + e["haze_21_9"]),
        "gloss_30": e["gloss_30"],
        "haze_narrow": 0.5 * (e["haze_28"] + e["haze_32"]),
        "haze_wide": 0.5 * (e["haze_25"] + e["haze_35"]),
        "doi": 100.0 * (e["gloss_30"] - e["r_30_3"]) / e["gloss_30"],
    }
    for key in out["e430"]:  # type: ignore[union-attr]
        models[f"e430.{key}"] = m.model(20.0 if key in ("gloss_20", "haze_18_1", "haze_21_9",
                                                        "haze_b") else 30.0, forced)  # fmt: skip
    out["models"] = models
    return out


def brdf(m: Map, forced: str, ti_deg: float = 45.0, cone_deg: float = 6.0) -> dict[str, object]:
    ti, lam = math.radians(ti_deg), 0.55
    model = m.model(ti_deg, forced)
    r = math.radians(cone_deg / 2)  # source and detector caps, half angle 3 deg
    tr_deg = np.arange(0.0, 70.0 + 1e-9, 1.0)
    os = m.padding(lam, (cone_deg, cone_deg), float(tr_deg.max()))
    alpha, beta, ok = m.angles(ti, lam, os)
    near = ok & (np.abs(beta) < 2 * r)
    a, cb = alpha[near], np.cos(beta[near])
    if model == "rayleigh-rice":
        p_rr = m.rayleigh_rice(ti, lam, os)[near]
    beam = m.coherent(ti, lam, model)
    lum = []
    for tr in np.radians(tr_deg):
        g = np.arccos(np.clip(cb * np.cos(a - tr), -1, 1))
        inside = g < 2 * r
        frac = lens(g[inside], r)
        if model == "kirchhoff":
            flux = float(np.sum(m.kirchhoff(ti, tr, lam, os)[near][inside] * frac))
        else:
            flux = float(np.sum(p_rr[inside] * frac))
        flux += beam * float(lens(np.array([abs(tr - ti)]), r)[0])
        lum.append(100.0 * flux)
    return {"theta_r_deg": tr_deg.tolist(), "luminance_pct": lum, "model": model}


def main(argv: list[str]) -> int:
    path, what = argv[0], argv[1]
    forced = argv[argv.index("--model") + 1] if "--model" in argv else "auto"
    m = Map(path)
    print(json.dumps(brdf(m, forced) if what == "brdf" else gloss(m, forced)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
