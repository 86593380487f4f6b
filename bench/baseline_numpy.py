"""Plain-numpy baseline of the facet model: what a numpy user writes without goniolab.

Run:  python bench/baseline_numpy.py MAP.npy brdf|gloss [--theta-i 45]

Reads a ``.npy`` height map (step from the ``.npy.json`` sidecar, else 1 um), levels it by
the closed-form least-squares plane, takes forward-difference slopes (one facet per pixel,
Wittmann et al. 2021 sec. 3.1), reflects every facet (mirror direction and radiometric
weight ``c F(c) / (m_z cos theta_i)``, real Fresnel) and then

- ``brdf``: histograms the mirror directions on a 0.05 deg (in-plane x out-of-plane) grid
  and reads 71 detector positions 0..70 deg with 6 deg source and detector cones (the
  planar circle-circle overlap of the source image and the detector on each grid node);
- ``gloss``: per incidence angle of the gloss report (20, 60, 85 and the E430 30 deg),
  the rectangle overlaps of every facet's source image with each receptor (ISO 2813 and
  E430, 12 readings).

It prints one JSON line (the curve or the readings) so that a bench can check it agrees
with goniolab. Float64 throughout, every step a whole-array numpy expression: the
baseline the whole-process timings of bench/bench_whole.py are compared with. It is not
the reference for accuracy (no first-order aperture term, nearest-node histogram); the
tests compare goniolab with independent truths instead.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np


def load(path: str) -> tuple[np.ndarray, float, float]:
    z = np.load(path)
    side = Path(path + ".json")
    dx = dy = 1.0
    if side.exists():
        info = json.loads(side.read_text())
        dx, dy = float(info["dx_um"]), float(info["dy_um"])
    return z, dx, dy


def facets(z: np.ndarray, dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
    ny, nx = z.shape
    x = (np.arange(nx) - (nx - 1) / 2.0) * dx
    y = (np.arange(ny) - (ny - 1) / 2.0) * dy
    b = float(z.sum(axis=0) @ x) / (ny * float(x @ x))
    c = float(z.sum(axis=1) @ y) / (nx * float(y @ y))
    z = z - z.mean() - b * x[None, :] - c * y[:, None]
    p = ((z[:-1, 1:] - z[:-1, :-1]) / dx).ravel()
    q = ((z[1:, :-1] - z[:-1, :-1]) / dy).ravel()
    return p, q


def fresnel(c: np.ndarray, n: float) -> np.ndarray:
    ct = np.sqrt(np.maximum(1.0 - (1.0 - c * c) / (n * n), 0.0))
    rs = (c - n * ct) / (c + n * ct)
    rp = (n * c - ct) / (n * c + ct)
    return 0.5 * (rs * rs + rp * rp)


def reflect(p: np.ndarray, q: np.ndarray, ti_deg: float, n: float):
    t = math.radians(ti_deg)
    wx, wz = math.sin(t), math.cos(t)
    inv = 1.0 / np.sqrt(1.0 + p * p + q * q)
    mx, my, mz = -p * inv, -q * inv, inv
    c = wx * mx + wz * mz
    ox, oy, oz = 2 * c * mx - wx, 2 * c * my, 2 * c * mz - wz
    keep = (c > 0) & (oz > 0)
    w = np.where(keep, c / (mz * wz) * fresnel(np.clip(c, 0.0, 1.0), n), 0.0)
    return ox, oy, oz, w


def brdf_curve(p, q, ti_deg=45.0, n=1.55, cone_deg=6.0, step_deg=0.05):
    ox, oy, oz, w = reflect(p, q, ti_deg, n)
    alpha = np.degrees(np.arctan2(-ox, oz))  # in-plane angle, > 0 specular side
    beta = np.degrees(np.arcsin(np.clip(oy, -1, 1)))
    reach = cone_deg  # source half angle + detector half angle
    a0, nb = -90.0, round(2 * reach / step_deg) + 1
    ia = np.rint((alpha - a0) / step_deg).astype(np.int64)
    ib = np.rint((beta + reach) / step_deg).astype(np.int64)
    na = round(180.0 / step_deg) + 1
    ok = (w > 0) & (ib >= 0) & (ib < nb)
    hist = np.bincount(ia[ok] * nb + ib[ok], weights=w[ok], minlength=na * nb).reshape(na, nb)
    a_nodes = a0 + step_deg * np.arange(na)
    b_nodes = np.radians(-reach + step_deg * np.arange(nb))
    r = math.radians(cone_deg / 2)  # both caps: half angle 3 deg
    out = []
    for tr in np.arange(0.0, 70.0 + 1e-9, 1.0):
        lo, hi = np.searchsorted(a_nodes, [tr - reach, tr + reach])
        da = np.radians(a_nodes[lo:hi] - tr)[:, None]
        g = np.arccos(np.clip(np.cos(b_nodes)[None, :] * np.cos(da), -1, 1))
        # planar lens area of two circles of radius r at distance g, over pi r^2
        with np.errstate(invalid="ignore", divide="ignore"):
            lens = 2 * r * r * np.arccos(np.clip(g / (2 * r), 0, 1)) - 0.5 * g * np.sqrt(
                np.maximum(4 * r * r - g * g, 0.0)
            )
        frac = np.where(g < 2 * r, lens / (math.pi * r * r), 0.0)
        out.append(100.0 * float(np.sum(hist[lo:hi] * frac)) / p.size)
    return out


def overlap(x, s, r):
    lo = np.maximum(x - 0.5 * s, -0.5 * r)
    hi = np.minimum(x + 0.5 * s, 0.5 * r)
    return np.maximum(hi - lo, 0.0) / s


GLOSS = {  # incidence: [(theta_r, source (in, perp), receptor (in, perp))] in deg
    20.0: [(20.0, (0.75, 2.5), (1.8, 3.6)), (18.1, (0.75, 2.5), (0.4, 3.6)),
           (21.9, (0.75, 2.5), (0.4, 3.6))],
    60.0: [(60.0, (0.75, 2.5), (4.4, 11.7))],
    85.0: [(85.0, (0.75, 2.5), (4.0, 6.0))],
    30.0: [(30.0, (0.05, 2.5), (0.14, 2.5)), (30.3, (0.05, 2.5), (0.14, 2.5)),
           (28.0, (0.05, 2.5), (0.4, 2.5)), (32.0, (0.05, 2.5), (0.4, 2.5)),
           (25.0, (0.05, 2.5), (0.4, 2.5)), (35.0, (0.05, 2.5), (0.4, 2.5))],
}  # fmt: skip


def gloss(p, q, n=1.55):
    out = {}
    for ti, readings in GLOSS.items():
        ox, oy, oz, w = reflect(p, q, ti, n)
        alpha = np.degrees(np.arctan2(-ox, oz))
        beta = np.degrees(np.arcsin(np.clip(oy, -1, 1)))
        ref = float(fresnel(np.array([math.cos(math.radians(ti))]), 1.567)[0])
        for tr, (s_in, s_pe), (r_in, r_pe) in readings:
            ov = overlap(alpha - tr, s_in, r_in) * overlap(beta, s_pe, r_pe)
            out[f"{ti:g}/{tr:g}"] = 100.0 * float(np.sum(w * ov)) / p.size / ref
    return out


def main(argv: list[str]) -> int:
    path, what = argv[0], argv[1]
    z, dx, dy = load(path)
    p, q = facets(z, dx, dy)
    del z
    result = brdf_curve(p, q) if what == "brdf" else gloss(p, q)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
