"""The wave models' work as tasks on up to two threads (issue 26: the 16-wavelength gloss).

:func:`run_reporting` runs tasks on :func:`goniolab.optics.facet_threads.run_tasks` (the
facet walks' threads and load rule) and sums the progress of tasks running at once into one
report; :func:`row_parts` cuts a pass over blocks of rows into tasks whose blocks stay those
of one pass; :class:`GlossTasks` is the wave models' ISO 2813 gloss, its geometries as tasks.
Every task forms its cells by the same operations whichever thread runs it and the callers
sum in one thread, so the numbers are the same bits on one thread and on two
(``tests/optics/test_wave_threads.py``).
"""

from __future__ import annotations

import functools
import itertools
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeVar

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.apertures import (
    ISO2813_BLACK_GLASS_N,
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
)
from goniolab.optics.coherent_beam import coherent_sums
from goniolab.optics.facet_threads import run_tasks

if TYPE_CHECKING:
    from goniolab.optics.facet import FacetModel
    from goniolab.optics.shared_map import SharedMap

__all__ = ["GlossTasks", "Progress", "row_parts", "run_reporting", "task_progress"]

FloatArray = NDArray[np.float64]
#: ``progress(done, total, what)``: called while long work runs.
Progress = Callable[[int, int, str], None]

T = TypeVar("T")

#: The progress slot of the task this thread runs (:func:`run_reporting`), if any.
_slot = threading.local()


class _JointProgress:
    """The ``(done, total, what)`` reports of tasks that run at once, added up into one
    report to ``fn`` (:func:`run_reporting`).

    Each task's successive stages (a new ``what``, or ``done`` going back) are added one
    after the other; ``done`` stays below the total until every task has ended, and the
    last report is ``(total, total, what)``, so a bar that closes at ``done >= total``
    (:class:`goniolab.progress.StepsProgress`) closes once, at the end. The reports reach
    ``fn`` one at a time (a lock), whichever thread makes them."""

    def __init__(self, fn: Progress, n_tasks: int) -> None:
        self.fn = fn
        self.lock = threading.Lock()
        #: per task: the totals of its ended stages, and its current (done, total, what)
        self.base = [0] * n_tasks
        self.now: list[tuple[int, int, str]] = [(0, 0, "")] * n_tasks
        self.what = ""

    def report(self, i: int, done: int, total: int, what: str) -> None:
        with self.lock:
            d0, t0, w0 = self.now[i]
            if w0 and (what != w0 or done < d0):  # task i went on to another stage
                self.base[i] += t0
            self.now[i] = (done, total, what)
            self.what = what
            all_done = sum(self.base) + sum(d for d, _, _ in self.now)
            all_total = sum(self.base) + sum(t for _, t, _ in self.now)
            self.fn(min(all_done, all_total - 1), all_total, what)

    def run(self, i: int, task: Callable[[], T]) -> T:
        return _carried(functools.partial(self.report, i), task)

    def close(self) -> None:
        with self.lock:
            total = sum(self.base) + sum(t for _, t, _ in self.now)
            if total:
                self.fn(total, total, self.what)


def row_parts(r0: int, r1: int, step: int, parts: int = 2) -> list[tuple[int, int]]:
    """Rows ``r0:r1`` in at most ``parts`` consecutive parts of whole blocks of ``step``
    rows (counted from ``r0``; the last block may be short): the tasks of a pass over
    blocks of rows, whose blocks stay those of one pass whatever the parts."""
    n_blocks = -(-(r1 - r0) // step)
    k = max(1, min(parts, n_blocks))
    cuts = [r0 + (n_blocks * j // k) * step for j in range(k)] + [r1]
    return [(a, b) for a, b in itertools.pairwise(cuts) if b > a]


def _carried(fn: Progress, task: Callable[[], T]) -> T:
    """``task()`` with ``fn`` as this thread's progress slot (the old slot back after)."""
    old = getattr(_slot, "fn", None)
    _slot.fn = fn
    try:
        return task()
    finally:
        _slot.fn = old


def run_reporting(tasks: Sequence[Callable[[], T]], progress: Progress | None = None) -> list[T]:
    """:func:`~goniolab.optics.facet_threads.run_tasks` (the same threads, the same load
    rule, results in the list's order) for tasks that report progress through a model's
    :attr:`PhysicalOpticsModel.progress`: while a task runs, that property hands it a
    slot of one :class:`_JointProgress`, so tasks running at once on two threads show as
    one bar that closes once (not two streams drawn over each other). Without
    ``progress`` the tasks keep the slot of the task that calls this (if any)."""
    if progress is None or len(tasks) < 2:
        # a task of an outer call keeps its slot on whichever thread its own tasks run
        carry = getattr(_slot, "fn", None)
        if carry is None:
            return run_tasks(tasks)
        return run_tasks([functools.partial(_carried, carry, task) for task in tasks])
    joint = _JointProgress(progress, len(tasks))
    out = run_tasks([functools.partial(joint.run, i, task) for i, task in enumerate(tasks)])
    joint.close()
    return out


def task_progress() -> Progress | None:
    """The progress slot of the :func:`run_reporting` task this thread runs (None: none)."""
    fn: Progress | None = getattr(_slot, "fn", None)
    return fn


class GlossTasks:
    """ISO 2813 gloss of a physical-optics model, its geometries as tasks (a base of
    :class:`goniolab.optics.physical.PhysicalOpticsModel`, which defines what is declared
    here)."""

    _shared: SharedMap

    @property
    def progress(self) -> Progress | None:
        raise NotImplementedError

    @property
    def facet_model(self) -> FacetModel:
        raise NotImplementedError

    @property
    def _g2_per_source(self) -> bool:
        raise NotImplementedError

    def _lams_for_gloss(self) -> tuple[FloatArray, FloatArray]:
        raise NotImplementedError

    def _lams_for_checks(self) -> list[float]:
        raise NotImplementedError

    def _route(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        source: Aperture,
        receptor: Aperture,
        lams_nm: Sequence[float],
    ) -> tuple[str, list[str]]:
        raise NotImplementedError

    def _sibling(self, kind: str) -> GlossTasks:
        raise NotImplementedError

    def _fractions(
        self,
        theta_i_deg: float,
        theta_r_deg: FloatArray,
        source: Aperture,
        receptor: Aperture,
        lams_nm: Sequence[float],
    ) -> FloatArray:
        raise NotImplementedError

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        """ISO 2813 gloss in GU, weighted over wavelength by C x V(lambda) (or one wavelength).

        ``G = 100 sum_l w_l Phi_l / Phi_std`` with ``Phi_l`` the flux fraction from the ISO
        source into the ISO receptor at wavelength l and ``Phi_std`` that of the polished
        black glass (n = 1.567) through the same apertures, as the instrument is calibrated:
        every source direction with its own Fresnel reflectance (within 3e-5 of the nominal
        ``F(1.567, t)``), so that the standard reads 100 exactly. :meth:`gloss_provenance`
        names the model of each geometry.
        """
        checks = self._lams_for_checks()
        # each geometry's model first (the routing is cheap), then the wave models'
        # readings as tasks on up to two threads (run_reporting; each reading is computed
        # as on one thread, the same bits); the facet model's in this thread, after
        plan: list[tuple[int, GlossTasks, str]] = []
        for t in angles_deg:
            key = int(t)
            if key not in ISO2813_RECEPTOR:
                raise ValueError(
                    f"no ISO 2813 geometry at {t} deg; known: {sorted(ISO2813_RECEPTOR)}"
                )
            model: GlossTasks = self
            who, _ = self._route(key, key, ISO2813_SOURCE, ISO2813_RECEPTOR[key], checks)
            while who not in ("self", "facet"):
                model = model._sibling(who)
                who, _ = model._route(
                    key, key, ISO2813_SOURCE, ISO2813_RECEPTOR[key], model._lams_for_checks()
                )
            plan.append((key, model, who))
        # the largest angle first: from ENERGY_CHECK_FROM_DEG on it carries the energy
        # check, the longest task, which then starts at once (the results keep their keys)
        wave = sorted(
            ((key, model) for key, model, who in plan if who == "self"), key=lambda km: -km[0]
        )
        for _, model in wave:
            model._warm()
        values = run_reporting(
            [functools.partial(model._gloss_at, key) for key, model in wave], self.progress
        )
        read = dict(zip([key for key, _ in wave], values, strict=True))
        out: dict[int, float] = {}
        for key, model, who in plan:
            out[key] = model.facet_model.gloss((key,))[key] if who == "facet" else read[key]
        return out

    def _warm(self) -> None:
        """Form the map's values every reading reads (its statistics, height bound and, with
        Kirchhoff's shadowing, the slope model of Smith's G2) before tasks read them on two
        threads."""
        sh = self._shared
        _ = sh.stats, sh.h_max_um
        if self._g2_per_source:  # (Rayleigh-Rice has no shadowing: no slope model)
            _ = sh.masking_model

    def _gloss_at(self, key: int) -> float:
        """ISO 2813 gloss at ``key`` deg computed by this model (:meth:`gloss`)."""
        lams, w = self._lams_for_gloss()
        rec = ISO2813_RECEPTOR[key]
        frac = self._fractions(key, np.array([float(key)]), ISO2813_SOURCE, rec, list(lams))
        ref = coherent_sums(
            key, 1.0, np.array([float(key)]), ISO2813_SOURCE, rec, ISO2813_BLACK_GLASS_N
        )[0]
        return 100.0 * float(np.sum(w * frac[:, 0]) / np.sum(w)) / ref
