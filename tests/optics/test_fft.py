"""The wave models' FFT (:mod:`goniolab.optics._fft`): scipy's pocketfft loaded without scipy,
checked against ``numpy.fft`` (an independent implementation of the same DFT)."""

from __future__ import annotations

import numpy as np
import pytest

from goniolab.optics import _fft


@pytest.mark.parametrize("dtype", [np.complex64, np.complex128])
@pytest.mark.parametrize("axis", [0, 1, -1])
def test_fft_is_the_dft_along_the_axis(dtype: type, axis: int) -> None:
    rng = np.random.default_rng(4)
    a = (rng.normal(size=(48, 40)) + 1j * rng.normal(size=(48, 40))).astype(dtype)
    got = _fft.fft(a, axis=axis)
    want = np.fft.fft(a.astype(np.complex128), axis=axis)
    assert got.dtype == dtype
    tol = 1e-4 if dtype == np.complex64 else 1e-11
    np.testing.assert_allclose(got, want, rtol=tol, atol=tol * float(np.abs(want).max()))
    assert _fft.BACKEND in ("pocketfft", "scipy.fft")


def test_a_strided_view_transforms_like_its_copy() -> None:
    a = (np.arange(64.0).reshape(8, 8) * (1 + 0.5j)).astype(np.complex64)[:, ::2]
    np.testing.assert_allclose(
        _fft.fft(a, axis=0), np.fft.fft(np.ascontiguousarray(a), axis=0), rtol=1e-5, atol=1e-3
    )


def test_the_module_is_loaded_without_the_scipy_package() -> None:
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import sys, numpy as np\n"
        "from goniolab.optics import _fft\n"
        "_fft.fft(np.ones((4, 4), dtype=np.complex64))\n"
        "print(_fft.BACKEND, 'scipy' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=Path(__file__).resolve().parents[2],
        capture_output=True,
        text=True,
        check=True,
    )
    backend, scipy_loaded = out.stdout.split()
    # the fallback imports scipy.fft; the direct module must not
    assert scipy_loaded == ("True" if backend == "scipy.fft" else "False")
