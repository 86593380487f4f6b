"""A small store of known content shared by the export, plot and api tests."""

from __future__ import annotations

from pathlib import Path

from goniolab.scan.plans import BrdfPlan
from goniolab.store import RunStore

T0 = 1_767_225_600.125  # 2026-01-01T00:00:00.125 UTC
WAVELENGTHS = [400.0, 550.0, 700.0]


def lum(k: int, r: int) -> float:
    return 10.0 * k + 0.5 * r + 0.25


def make_store(path: Path) -> Path:
    """Write ``path``: run 1, a 3-angle x 2-repeat scan with spectra missing its last
    reading; run 2, a gloss log of two readings."""
    plan = BrdfPlan(45.0, (40.0, 45.0, 50.0), repeats=2, sample="sample:x")
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={"lab": {"name": "t"}},
                           sample="sample:x", model={"n": 1.55}, version="9.9")  # fmt: skip
        for k, tr in enumerate(plan.theta_r_deg):
            for r in range(2):
                if (k, r) == (2, 1):
                    continue
                s.add_point(rid, index=k, repeat=r, theta_i_deg=45.0, theta_r_deg=tr,
                            measured_theta_i_deg=45.01, measured_theta_r_deg=tr + 0.02,
                            luminance_pct=lum(k, r),
                            raw={"wavelengths_nm": WAVELENGTHS, "values": [k, r, 7.0]},
                            timestamp=T0 + 2 * k + r)  # fmt: skip
        s.add_predictions(rid, [(0, 45.0, 40.0, 1.0), (1, 45.0, 45.0, 12.0), (2, 45.0, 50.0, 3.0)])
        s.set_status(rid, "aborted", "aborted by the operator")
        gid = s.create_run(kind="gloss", plan={"kind": "gloss", "angles_deg": [20, 60, 85]},
                           config={}, sample="sample:g", model={}, version="9.9")  # fmt: skip
        for j in range(2):
            s.add_gloss_reading(gid, values_gu={20: 80.0 + j, 60: 90.0 + j, 85: 95.0},
                                temperature_c=21.5, predicted_gu={20: 81.0, 60: 91.0, 85: 96.0},
                                raw="line", timestamp=T0 + 60 * j)  # fmt: skip
    return path
