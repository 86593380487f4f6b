"""The time left in a run, from the measured rates of the parts of its readings (issue 27).

A reading is made of parts: the arm move before it (if any), the dwell that lets the arms
settle, the reading itself (exposure, transfer, colour, the store's commit) and the rest of
the loop ("other": events, checks). Each part kind has a :class:`PartRate`: a line
``wall_s = a + b x`` in the part's *model* size ``x`` (the motion model's lab seconds of a
move, :func:`drivers.timing.trapezoid_duration_s`, or its degrees where no motion model is
known; the dwell's and the exposure's lab seconds; 1 for "other"), fitted robustly to the
latest parts measured. Before a part kind was measured its prior is the model's lab seconds
converted to wall seconds by the clock's scale (``x / scale``); at an instant sim
clock (scale 0) a sleep takes no wall time, so moves and dwells start at 0 s and a reading,
whose wall time is then the computing alone, is unknown (NaN, shown as "?") until two
were timed. The estimate therefore converges to the run's real pace whatever the clock: the
slow arm, the bus latency, the twin's computing at ``--time-scale 0``.

Time is wall time (:class:`WallTime`), what the user waits: :class:`~goniolab.scan.events.
Progress` ``eta_s`` carries it. Time spent paused (the operator's pause, a store outage) or
swapping the specimen (an operator's hands) is left out of every part, so a pause neither
stretches nor shrinks the estimate.

:class:`EtaEstimator` is the one estimator of the scan runner
(:class:`goniolab.scan.runner.ScanRunner`) and the alignment
(:class:`goniolab.scan.align.AlignRunner`).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Literal

__all__ = [
    "WINDOW",
    "EtaEstimator",
    "PartKind",
    "PartRate",
    "PointParts",
    "WallTime",
    "lower_median",
    "trimmed_mean",
]

PartKind = Literal["move", "dwell", "reading", "other"]


@dataclass(frozen=True, slots=True)
class WallTime:
    """The clock an ETA is measured on, and how many of its seconds a lab-clock second of
    a sleep takes (``per_lab_s``: ``1 / scale`` of a sim clock, 1 for real instruments, 0
    at an instant sim clock)."""

    now: Callable[[], float] = time.monotonic
    per_lab_s: float = 1.0

    @classmethod
    def of(cls, clock: object) -> WallTime:
        """Wall time (``time.monotonic``) against a lab clock of ``clock.scale`` lab
        seconds per wall second (:class:`drivers.timing.SimClock`; a clock without a
        scale runs in real time)."""
        scale = float(getattr(clock, "scale", 1.0))
        return cls(time.monotonic, 1.0 / scale if scale > 0 else 0.0)


#: A first part this many times slower than its prior (plus 1 s) is taken as a warm-up.
WARM_UP_FACTOR = 10.0

#: How many of the latest parts of a kind its rate is fitted to: the run's recent pace.
WINDOW = 32


def lower_median(values: Sequence[float]) -> float:
    """The median, the lower of the two middle values for an even count."""
    ordered = sorted(values)
    return ordered[(len(ordered) - 1) // 2]


def trimmed_mean(values: Sequence[float]) -> float:
    """The mean without the largest value(s) (one in 16, at least one of two or more): a
    first reading carries one-off costs (the twin's JIT compilation took 2.4 s against
    0.01-0.1 s per later reading), while a sum of parts needs their mean, not their median
    (auto-exposure makes the readings' times skewed)."""
    ordered = sorted(values)
    if len(ordered) >= 2:
        ordered = ordered[: len(ordered) - max(1, len(ordered) // 16)]
    return math.fsum(ordered) / len(ordered)


@dataclass(slots=True)
class PartRate:
    """Wall seconds of one part kind as a line ``a + b x`` in its model size ``x``.

    Fitted robustly to the latest :data:`WINDOW` parts: ``b`` the :func:`lower_median` of
    the slopes between parts of different sizes (kept >= 0; Theil 1950, Sen 1968), ``a``
    the :func:`trimmed_mean` of the parts' excess ``w - b x``, so a one-off slow part (a
    warm-up, a hiccup of the machine) does not set the pace. With one size only, ``b`` is the prior slope (a
    constant overhead per part on top of the model), or without a prior the time is in
    proportion to the size. Before any part was measured: ``prior_per_x * x``, also after
    one part that took far longer than its prior (a warm-up: the first reading of a run
    took 3-5 s of model set-up and JIT compilation, the next ones 0.02 s, and alone it
    said "ETA 65 s" for a run 8 s from its end); without a prior (``None``) NaN until two
    parts were measured.
    """

    prior_per_x: float | None
    samples: deque[tuple[float, float]] = field(default_factory=lambda: deque(maxlen=WINDOW))
    #: the fitted line (intercept, slope); slope ``None``: in proportion to the size
    _line: tuple[float, float | None] = (0.0, 0.0)

    @property
    def n(self) -> int:
        """Parts measured in the window."""
        return len(self.samples)

    def add(self, x: float, wall_s: float) -> None:
        """One part of size ``x`` took ``wall_s`` wall seconds."""
        self.samples.append((x, wall_s))
        pts = list(self.samples)
        slopes = [
            (wj - wi) / (xj - xi)
            for i, (xi, wi) in enumerate(pts)
            for xj, wj in pts[i + 1 :]
            if abs(xj - xi) > 1e-9 * max(1.0, abs(xi), abs(xj))
        ]
        if slopes:
            b = max(0.0, lower_median(slopes))
        elif self.prior_per_x is not None:
            b = self.prior_per_x
        else:  # one size, no model: in proportion to the size (a size 0: a constant)
            sized = [w / x for x, w in pts if x > 0]
            if sized:
                self._line = (trimmed_mean(sized), None)
            else:
                self._line = (trimmed_mean([w for _, w in pts]), 0.0)
            return
        self._line = (trimmed_mean([w - b * x for x, w in pts]), b)

    def _warm_up(self) -> bool:
        """The only part measured took over ``WARM_UP_FACTOR`` times its prior plus 1 s:
        a warm-up (the model's set-up, JIT compilation), not the run's pace."""
        assert self.prior_per_x is not None
        x, w = self.samples[0]
        return w > WARM_UP_FACTOR * self.prior_per_x * x + 1.0

    def predict(self, x: float) -> float:
        """Wall seconds of a part of size ``x`` (>= 0; NaN: not known yet)."""
        if self.prior_per_x is None:
            if len(self.samples) < 2:
                return math.nan  # one part alone may be the run's warm-up: not a pace yet
        elif not self.samples or (len(self.samples) == 1 and self._warm_up()):
            return self.prior_per_x * x
        a, b = self._line
        if b is None:
            return a * x
        return max(0.0, a + b * x)


@dataclass(frozen=True, slots=True)
class PointParts:
    """One reading's parts in their model sizes: the move before it (``None``: none), the
    dwell after that move and the reading (lab seconds)."""

    move_x: float | None
    dwell_lab_s: float
    reading_lab_s: float


@dataclass
class EtaEstimator:
    """Wall seconds left in a run of ``points`` (in order) and a final move of size
    ``park_x`` (``None``: the run ends with its last reading).

    The run reports its parts as they happen: :meth:`begin_point`, then each part inside
    :meth:`part` (timed on ``wall``), then :meth:`end_point` returns the time left; a pause
    or a specimen swap lies between :meth:`pause` and :meth:`resume`. A run whose
    readings are not known in advance (an alignment) calls :meth:`finish_point` and asks
    :meth:`left_s` of the readings it expects. ``move_known``:
    the move sizes are the motion model's lab seconds (their prior is ``x / scale``);
    ``False``: degrees of travel, with no prior.
    """

    points: Sequence[PointParts]
    park_x: float | None = None
    wall: WallTime = field(default_factory=WallTime)
    move_known: bool = True
    rates: dict[str, PartRate] = field(init=False)
    paused_s: float = field(default=0.0, init=False)
    _paused_at: float | None = field(default=None, init=False)
    _point: tuple[float, float, float] | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        per_lab = self.wall.per_lab_s
        self.rates = {
            "move": PartRate(per_lab if self.move_known else None),
            "dwell": PartRate(per_lab),
            # at an instant clock the reading's wall time is computing alone: unknown
            "reading": PartRate(per_lab if per_lab > 0 else None),
            "other": PartRate(0.0),
        }

    # ------------------------------------------------------------------ measuring
    def _excluded_s(self) -> float:
        now = self.wall.now()
        return self.paused_s + (0.0 if self._paused_at is None else now - self._paused_at)

    def pause(self) -> None:
        """The run waits for someone (a pause, a store outage, a specimen swap)."""
        if self._paused_at is None:
            self._paused_at = self.wall.now()

    def resume(self) -> None:
        """The run goes on; the wait since :meth:`pause` is left out of every part."""
        if self._paused_at is not None:
            self.paused_s += max(0.0, self.wall.now() - self._paused_at)
            self._paused_at = None

    def begin_point(self) -> None:
        """The first reading's loop begins (before its pause check and its move; each
        :meth:`finish_point` begins the next one's)."""
        self._point = (self.wall.now(), self._excluded_s(), 0.0)

    def start_part(self) -> tuple[float, float]:
        """A part begins: the mark to pass to :meth:`finish_part`."""
        return self.wall.now(), self._excluded_s()

    def finish_part(self, kind: PartKind, x: float, mark: tuple[float, float]) -> None:
        """The part of kind ``kind`` and size ``x`` begun at ``mark`` is done."""
        wall_s = max(0.0, self.wall.now() - mark[0] - (self._excluded_s() - mark[1]))
        self.rates[kind].add(x, wall_s)
        if self._point is not None:
            start, excluded, parts = self._point
            self._point = (start, excluded, parts + wall_s)

    @contextmanager
    def part(self, kind: PartKind, x: float) -> Iterator[None]:
        """Time the part of kind ``kind`` and size ``x`` done inside the block (a block
        that raises is not measured)."""
        mark = self.start_part()
        yield
        self.finish_part(kind, x, mark)

    def finish_point(self) -> None:
        """A reading is stored: the rest of its loop counts as "other", and the next
        reading's loop begins."""
        if self._point is not None:
            start, excluded, parts = self._point
            total = self.wall.now() - start - (self._excluded_s() - excluded)
            self.rates["other"].add(1.0, max(0.0, total - parts))
        self.begin_point()

    def end_point(self, k: int) -> float:
        """Reading ``k`` (0-based in ``points``) is stored (:meth:`finish_point`): the
        wall seconds left (:meth:`left_after`)."""
        self.finish_point()
        return self.left_after(k)

    # ------------------------------------------------------------------ predicting
    def point_s(self, p: PointParts) -> float:
        """Predicted wall seconds of one reading with all its parts."""
        t = self.rates["reading"].predict(p.reading_lab_s) + self.rates["other"].predict(1.0)
        if p.move_x is not None:
            t += self.rates["move"].predict(p.move_x) + self.rates["dwell"].predict(p.dwell_lab_s)
        return t

    def left_s(self, start: int) -> float:
        """Predicted wall seconds of ``points[start:]`` and the final move (NaN: a part
        is not known yet)."""
        t = math.fsum(self.point_s(p) for p in self.points[start:])
        if self.park_x is not None:
            t += self.rates["move"].predict(self.park_x)
        return t

    @property
    def total_s(self) -> float:
        """The whole run's predicted wall seconds."""
        return self.left_s(0)

    def left_after(self, k: int) -> float:
        """Predicted wall seconds left once reading ``k`` (0-based) is stored."""
        return self.left_s(k + 1)
