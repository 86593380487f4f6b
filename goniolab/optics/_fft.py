"""Complex FFTs along one axis for the physical-optics models, without importing scipy.

The wave models (:mod:`goniolab.optics.kirchhoff`, :mod:`goniolab.optics.rayleigh_rice`)
spend their time in complex64 FFTs of 1024-point rows. scipy's pocketfft does one 1024 x
1024 pass in about 2 ms, numpy's in about 8 ms (numpy 2.4, this 2-core machine,
``bench/bench_lean.py --fft``), but ``import scipy.fft`` costs a process about 0.25 s
(it loads ``scipy.special`` and the array-API layer), as much as the transforms of a
whole 71-point curve.

:func:`fft` therefore calls scipy's compiled pocketfft module
(``scipy/fft/_pocketfft/pypocketfft*.so``, the code ``scipy.fft.fft`` runs) loaded by
itself, without the ``scipy`` package around it (under 1 ms). The module is private to
scipy, so it is used only when it is found, accepts the call, and transforms a test
vector as ``numpy.fft.fft`` does (to 1e-5); otherwise ``scipy.fft.fft`` is used.
:data:`BACKEND` names the one in use (``"pocketfft"`` or ``"scipy.fft"``); both give the
same values to float rounding (``tests/optics/test_fft.py``).
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["BACKEND", "fft", "fft_into"]

_C2C: Callable[..., Any] | None = None
#: The FFT in use: ``"pocketfft"`` (scipy's compiled module alone) or ``"scipy.fft"``.
BACKEND: str = ""


def _load_pocketfft() -> Callable[..., Any] | None:
    """scipy's ``pypocketfft.c2c``, loaded without importing scipy, or None."""
    try:
        spec = importlib.util.find_spec("scipy")
        if spec is None or not spec.submodule_search_locations:
            return None
        folder = os.path.join(spec.submodule_search_locations[0], "fft", "_pocketfft")
        names = [
            f
            for f in os.listdir(folder)
            if f.startswith("pypocketfft.") and f.endswith((".so", ".pyd"))
        ]
        if len(names) != 1:
            return None
        path = os.path.join(folder, names[0])
        loader = importlib.machinery.ExtensionFileLoader("pypocketfft", path)
        mspec = importlib.util.spec_from_file_location("pypocketfft", path, loader=loader)
        if mspec is None:
            return None
        module = importlib.util.module_from_spec(mspec)
        loader.exec_module(module)
        c2c: Callable[..., Any] = module.c2c
        probe = np.exp(1j * np.arange(12.0) ** 1.5).astype(np.complex64).reshape(2, 6)
        got = c2c(probe, (1,), True, 0, None, 1)
        if got.shape != probe.shape or not np.allclose(
            got, np.fft.fft(probe, axis=1), rtol=1e-5, atol=1e-5
        ):
            return None
        return c2c
    except Exception:  # any failure: scipy.fft is used instead
        return None


def _backend() -> Callable[..., Any] | None:
    global _C2C, BACKEND
    if not BACKEND:
        _C2C = _load_pocketfft()
        BACKEND = "pocketfft" if _C2C is not None else "scipy.fft"
    return _C2C


def fft(a: NDArray[Any], axis: int = -1) -> NDArray[Any]:
    """``scipy.fft.fft(a, axis=axis)`` of a complex array (same dtype out), unnormalised."""
    c2c = _backend()
    if c2c is not None:
        out: NDArray[Any] = c2c(a, (axis % a.ndim,), True, 0, None, 1)
        return out
    import scipy.fft

    result: NDArray[Any] = scipy.fft.fft(a, axis=axis, workers=-1)
    return result


def fft_into(a: NDArray[Any], axis: int, out: NDArray[Any]) -> None:
    """:func:`fft` of ``a`` along ``axis`` written into ``out`` (same shape and dtype; either
    may be a strided view, as a few columns of a larger array): no new array per call."""
    c2c = _backend()
    if c2c is not None:
        c2c(a, (axis % a.ndim,), True, 0, out, 1)
        return
    import scipy.fft

    out[...] = scipy.fft.fft(a, axis=axis, workers=-1)
