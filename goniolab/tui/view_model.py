"""The TUI's data, and what it needs from the lab as a small Protocol (no Textual here).

The scan form (:class:`ScanSetup`), an arm's status (:class:`ArmState`), a row of the runs
browser (:class:`RunSummary`) and a stored run (:class:`StoredRun`). The app never talks
to drivers, the runner or the store directly: it calls a :class:`Backend` and consumes
the backend's :class:`~goniolab.scan.events.EventBus`.
:class:`goniolab.tui.session_backend.SessionBackend` implements it over a real or simulated
:class:`~goniolab.lab_wiring.Lab`; tests may implement it with a scripted publisher.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable
from dataclasses import dataclass, field
from typing import Any, Protocol

from goniolab.errors import UserError
from goniolab.scan.events import (
    ColourPredicted,
    EventBus,
    GlossRead,
    PointMeasured,
    PointPredicted,
)
from goniolab.scan.plans import PlanError, angle_range

__all__ = ["ArmState", "Backend", "RunIdentity", "RunSummary", "ScanSetup", "StoredRun"]


@dataclass(frozen=True, slots=True)
class RunIdentity:
    """Who measures which physical sample, with notes and tags: stored with every run the
    TUI starts (scans and gloss logs) until changed (key ``i``); the config's ``[run]``
    table fills what is left empty."""

    operator: str = ""
    sample_id: str = ""
    notes: str = ""
    tags: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line for the user ("" when nothing is set)."""
        parts = [
            f"operator {self.operator}" if self.operator else "",
            f"sample id {self.sample_id}" if self.sample_id else "",
            f"tags {', '.join(self.tags)}" if self.tags else "",
            "notes" if self.notes else "",
        ]
        return "; ".join(p for p in parts if p)


#: The setup form's label of each field: what an error names (not the attribute name).
FIELD_LABELS = {
    "theta_i_deg": "θi",
    "theta_r_start_deg": "θr from",
    "theta_r_stop_deg": "θr to",
    "theta_r_step_deg": "θr step",
    "repeats": "repeats",
}


@dataclass(frozen=True, slots=True)
class ScanSetup:
    """The scan form: an in-plane BRDF scan at one incidence angle.

    Attributes
    ----------
    sample
        Sample spec (``sample:NAME`` or a height-map path) used for the prediction.
    theta_i_deg
        Incidence angle (lamp arm) in degrees.
    theta_r_start_deg, theta_r_stop_deg, theta_r_step_deg
        Detector sweep in degrees, signed (> 0 specular side), stop included.
    repeats
        Readings per point (their scatter is drawn as min/max bars).
    """

    sample: str
    theta_i_deg: float
    theta_r_start_deg: float
    theta_r_stop_deg: float
    theta_r_step_deg: float
    repeats: int

    def validate(self) -> None:
        """Raise :class:`UserError` naming the form field and the reason when a value
        cannot make a sweep (not a number, step, order, repeats, too many angles).

        Whether the arms can reach the sweep is the lab's question, not the form's:
        :meth:`Backend.check_setup` asks it with the lab config's limits, in the words of
        ``goniolab scan`` (:func:`goniolab.app.lab_setup.check_reach`).
        """
        values = {
            "theta_i_deg": self.theta_i_deg,
            "theta_r_start_deg": self.theta_r_start_deg,
            "theta_r_stop_deg": self.theta_r_stop_deg,
            "theta_r_step_deg": self.theta_r_step_deg,
        }
        for name, value in values.items():
            if not math.isfinite(value):
                raise UserError(
                    f"scan setup: {FIELD_LABELS[name]} must be a finite number, got {value}"
                )
        if not self.sample:
            raise UserError("scan setup: sample: choose a sample")
        if self.theta_r_step_deg <= 0.0:
            raise UserError(f"scan setup: θr step must be > 0 deg, got {self.theta_r_step_deg:g}")
        if self.theta_r_stop_deg < self.theta_r_start_deg:
            raise UserError(
                "scan setup: θr to must be >= θr from, got "
                f"{self.theta_r_stop_deg:g} < {self.theta_r_start_deg:g}"
            )
        if self.repeats < 1:
            raise UserError(f"scan setup: repeats must be >= 1, got {self.repeats}")
        try:
            self.theta_r_values_deg()  # refuses a sweep of more than MAX_ANGLES angles
        except PlanError as exc:
            raise UserError(str(exc)) from None

    def theta_r_values_deg(self) -> list[float]:
        """The detector angles of the sweep, start to stop inclusive, in degrees
        (:func:`goniolab.scan.plans.angle_range`)."""
        return list(
            angle_range(
                self.theta_r_start_deg,
                self.theta_r_stop_deg,
                self.theta_r_step_deg,
                name="scan setup: theta_r",
            )
        )


@dataclass(frozen=True, slots=True)
class ArmState:
    """One arm as the status panel shows it."""

    name: str
    position_deg: float | None
    moving: bool
    homed: bool
    alarm_code: int | None
    connected: bool
    message: str = ""


@dataclass(frozen=True, slots=True)
class RunSummary:
    """One row of the runs browser."""

    run_id: int
    started: float  # unix time
    kind: str
    sample: str
    status: str
    n_points: int


@dataclass(frozen=True, slots=True)
class StoredRun:
    """A stored run, as events, so the same :class:`Comparison` code can show it."""

    summary: RunSummary
    measured: list[PointMeasured] = field(default_factory=list)
    predicted: list[PointPredicted] = field(default_factory=list)
    gloss: list[GlossRead] = field(default_factory=list)
    #: Predicted colours per plan point (issue 11; empty for older runs).
    colours: list[ColourPredicted] = field(default_factory=list)
    #: The run's stored prediction record (``computed_by``: which model computed each angle;
    #: :attr:`goniolab.tui.comparison.Comparison.prediction_record`).
    prediction: dict[str, Any] = field(default_factory=dict)


class Backend(Protocol):
    """The lab as the TUI sees it. Every device call may raise ``drivers.base.DeviceError``."""

    bus: EventBus

    @property
    def title(self) -> str:
        """A one-line description of the lab (config name, mode)."""
        ...

    async def open(self) -> None:
        """Connect the instruments and home the goniometer."""
        ...

    async def close(self) -> None:
        """Stop any run and release the instruments."""
        ...

    async def home(self) -> None:
        """Reset the arms' alarms and home the goniometer again (connecting first if
        :meth:`open` failed before the instruments were reached)."""
        ...

    #: Stored with every run started from now on (scans, gloss logs).
    run_identity: RunIdentity

    def sample_names(self) -> list[str]:
        """Built-in samples for the picker (without the ``sample:`` prefix)."""
        ...

    def default_setup(self) -> ScanSetup:
        """The form's initial values (from the config)."""
        ...

    def check_setup(self, setup: ScanSetup) -> None:
        """Raise :class:`UserError` when ``setup`` is invalid or out of the arms' reach
        (the form calls it as it is typed; :meth:`start` refuses the same)."""
        ...

    @property
    def sample_note(self) -> str:
        """One line under the sample picker saying what the instruments measure."""
        ...

    async def predict_curve(self, setup: ScanSetup) -> list[float]:
        """The model's luminance in % of a mirror for ``setup.sample`` at every detector
        angle of the sweep (``setup.theta_r_values_deg()``), computed off the event loop."""
        ...

    @property
    def running(self) -> bool:
        """A run is in progress (running or paused)."""
        ...

    async def start(self, setup: ScanSetup) -> int:
        """Start a scan in the background; return its run id. Raises UserError on bad setup."""
        ...

    async def align(self, sample: str) -> int:
        """Start an alignment (``scan --plan align``: black-glass standard, then
        ``sample``) in the background; return its run id. Its result is published with
        the run's ``RunFinished``, written into the config's ``[alignment]`` and applied to
        later moves. Raises UserError when a run is in progress or the setup is bad."""
        ...

    def pause(self) -> None:
        """Ask the runner to pause after the current point."""
        ...

    def resume(self) -> None:
        """Ask a paused runner to continue."""
        ...

    def abort(self) -> None:
        """Ask the runner (scan or alignment) to stop after the current point (run marked
        aborted)."""
        ...

    async def arm_states(self) -> tuple[ArmState, ArmState]:
        """Lamp and detector arm status, read from the instrument."""
        ...

    async def read_gloss(self, sample: str) -> Awaitable[None] | None:
        """Start one glossmeter reading (published as GlossRead with the prediction of
        ``sample``); a request while one is under way is coalesced into the next reading,
        never refused. Returns what completes once the reading is stored (None: at
        once)."""
        ...

    def list_runs(self) -> list[RunSummary]:
        """Stored runs, newest first (blocking: call from a thread worker)."""
        ...

    def load_run(self, run_id: int) -> StoredRun:
        """One stored run's readings, predictions and gloss (blocking: thread worker)."""
        ...

    def prediction_record(self, run_id: int) -> dict[str, Any]:
        """Run ``run_id``'s stored prediction record (its ``computed_by``: which model
        computed each angle's prediction and colour), {} when it has none (blocking:
        thread worker)."""
        ...

    def prediction_models(self, run_id: int) -> str:
        """Which model computes run ``run_id``'s predicted curve (``"facet"``, or
        ``"facet 0-38 deg, kirchhoff 40-70 deg"``), "" when unknown (blocking: thread)."""
        ...
