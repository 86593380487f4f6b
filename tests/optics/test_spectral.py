"""The ISO 2813 spectral weights: CIE illuminant C x V(lambda) (goniolab/optics/iso2813_weighting.py)."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np

from goniolab.optics.iso2813_weighting import (
    CIE_C_AT_WAVELENGTHS,
    CIE_V_AT_WAVELENGTHS,
    ISO2813_WAVELENGTHS_NM,
    iso2813_weights,
)


def test_the_written_out_cie_values_are_colour_sciences_tables() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
        from colour.colorimetry import SDS_LEFS_PHOTOPIC

    lam = np.asarray(ISO2813_WAVELENGTHS_NM)
    c = np.asarray(colour.SDS_ILLUMINANTS["C"][lam])
    v = np.asarray(SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"][lam])
    np.testing.assert_allclose(CIE_C_AT_WAVELENGTHS, c, rtol=1e-9)
    np.testing.assert_allclose(CIE_V_AT_WAVELENGTHS, v, rtol=1e-9)
    # another grid is read from colour-science and normalised the same way
    lam2, w2 = iso2813_weights((500.0, 550.0, 600.0))
    c2 = np.asarray(colour.SDS_ILLUMINANTS["C"][lam2])
    v2 = np.asarray(SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"][lam2])
    np.testing.assert_allclose(w2, c2 * v2 / np.sum(c2 * v2), rtol=1e-12)


def test_weights_peak_near_555_nm_and_sum_to_one() -> None:
    lam, w = iso2813_weights()
    assert abs(w.sum() - 1.0) < 1e-12
    assert lam[int(np.argmax(w))] == 560.0  # V peaks at 555 nm; C is flat there
    assert not w.flags.writeable


def test_the_default_weights_do_not_import_colour_science() -> None:
    code = (
        "import sys; from goniolab.optics.iso2813_weighting import iso2813_weights; iso2813_weights(); "
        "print('colour' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
