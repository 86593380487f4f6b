"""A scripted stand-in for the lab: publishes the runner's events from a known curve.

Measured and predicted curves are analytic Gaussians, so the tests know the truth:
peak amplitude ``AMP_PCT`` at ``PEAK_DEG``, FWHM ``2 sqrt(2 ln 2) SIGMA_DEG``, and each
point's repeats are ``mean - SPREAD_PCT``, ``mean``, ``mean + SPREAD_PCT`` (repeats = 3).
Points advance only when the test releases them (``release(n)``), so pause/resume and
abort are tested without sleeps or races.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import Any, ClassVar

from textual.pilot import Pilot

from drivers.base import DeviceTimeout
from goniolab.errors import UserError
from goniolab.scan.events import (
    ArmsMoved,
    EventBus,
    GlossRead,
    InstrumentError,
    PointMeasured,
    PointPredicted,
    Progress,
    RunFinished,
    RunStarted,
    RunState,
    StateChanged,
)
from goniolab.tui.app import GonioApp
from goniolab.tui.view_model import ArmState, RunIdentity, RunSummary, ScanSetup, StoredRun

AMP_PCT = 40.0
PEAK_DEG = 20.0
SIGMA_DEG = 3.0
PRED_SCALE = 0.9  # predicted = PRED_SCALE * measured mean
SPREAD_PCT = 0.5
#: Preview prediction of each scripted sample, relative to the scan's PRED_SCALE curve.
PREVIEW_SCALE = {"sample:wittmann-3": 1.0, "sample:wittmann-1": 0.5, "sample:flat": 2.0}
T0 = 1_767_225_600.0  # 2026-01-01 00:00:00 UTC: fixed timestamps for snapshots


def gaussian_pct(theta_r_deg: float) -> float:
    """The scripted measured mean: AMP_PCT exp(-(t - PEAK)^2 / (2 SIGMA^2))."""
    return AMP_PCT * math.exp(-((theta_r_deg - PEAK_DEG) ** 2) / (2.0 * SIGMA_DEG**2))


class ScriptedBackend:
    """Implements :class:`goniolab.tui.view_model.Backend` with a scripted event publisher."""

    def __init__(
        self, *, gated: bool = True, fail_open: bool = False, hold_open: bool = False
    ) -> None:
        self.bus = EventBus()
        self.run_identity = RunIdentity()
        #: With ``hold_open``, open() (connect and home) returns only once this is set.
        self.homed = asyncio.Event()
        if not hold_open:
            self.homed.set()
        self.gated = gated
        self.fail_open = fail_open
        self._allowed = 0
        self._gate = asyncio.Condition()
        self._paused = False
        self._resume = asyncio.Event()
        self._resume.set()
        self._abort = False
        self._task: asyncio.Task[None] | None = None
        self.opened = False
        self.closed = False
        self.setups: list[ScanSetup] = []
        self.position = (45.0, 45.0)
        self.stored: dict[int, StoredRun] = {}
        self.gloss_samples: list[str] = []
        self.previews: list[ScanSetup] = []
        #: the scan's warnings, as its RunFinished summary carries them (the runner's log)
        self.run_warnings: list[str] = []
        self.homings = 0

    @property
    def title(self) -> str:
        return "scripted lab"

    async def open(self) -> None:
        await self.homed.wait()
        if self.fail_open:
            raise DeviceTimeout("no answer to homing within 30.0 s", device="lamp")
        self.opened = True

    async def home(self) -> None:
        self.homings += 1
        await self.open()

    async def close(self) -> None:
        self.closed = True
        if self._task is not None:
            self._abort = True
            self._resume.set()
            async with self._gate:
                self._allowed = 10**9
                self._gate.notify_all()
            await self._task

    def sample_names(self) -> list[str]:
        return ["flat", "wittmann-1", "wittmann-3"]

    def prediction_models(self, run_id: int) -> str:
        return "scripted-gaussian"

    def prediction_record(self, run_id: int) -> dict[str, Any]:
        return {"computed_by": {"scripted-gaussian": []}}

    def default_setup(self) -> ScanSetup:
        return ScanSetup("sample:wittmann-3", 20.0, 10.0, 30.0, 2.0, 3)

    @property
    def sample_note(self) -> str:
        return "the scripted lab measures the selected sample"

    def check_setup(self, setup: ScanSetup) -> None:
        """The form's own checks only: the scripted lab has no arm limits."""
        setup.validate()

    async def predict_curve(self, setup: ScanSetup) -> list[float]:
        """PREVIEW_SCALE[sample] x PRED_SCALE x the scripted Gaussian."""
        setup.validate()
        self.previews.append(setup)
        scale = PREVIEW_SCALE[setup.sample]
        return [scale * PRED_SCALE * gaussian_pct(t) for t in setup.theta_r_values_deg()]

    @property
    def running(self) -> bool:
        return self._task is not None and not self._task.done()

    async def start(self, setup: ScanSetup) -> int:
        setup.validate()
        if self.running:
            raise UserError("a scan is already running")
        self.setups.append(setup)
        run_id = len(self.setups)
        self._abort = False
        self._task = asyncio.get_running_loop().create_task(self._run(run_id, setup))
        return run_id

    #: What the scripted alignment "finds" (its RunFinished summary).
    ALIGNMENT: ClassVar[dict[str, object]] = {
        "lamp_zero_deg": 0.125,
        "detector_zero_deg": -0.25,
        "sample_tilt_deg": 0.5,
        "state_file": "/srv/lab/lab.alignment.toml",
    }

    async def align(self, sample: str) -> int:
        """A scripted alignment: 3 readings (gated like a scan's points), then ALIGNMENT."""
        if self.running:
            raise UserError("a run is already in progress")
        self.setups.append(ScanSetup(sample, 20.0, 15.0, 25.0, 5.0, 1))
        run_id = len(self.setups)
        self._abort = False
        self._task = asyncio.get_running_loop().create_task(self._align(run_id))
        return run_id

    async def _align(self, run_id: int) -> None:
        pub = self.bus.publish
        pub(RunStarted(run_id=run_id, kind="align", total_points=3, plan={}, sample=""))
        pub(StateChanged(run_id=run_id, state=RunState.RUNNING))
        for index, tr in enumerate((15.0, 20.0, 25.0)):
            if self.gated:
                async with self._gate:
                    await self._gate.wait_for(lambda: self._allowed > 0)
                    self._allowed -= 1
            if self._abort:
                pub(RunFinished(run_id=run_id, state=RunState.ABORTED, reason="", summary={}))
                return
            pub(
                PointMeasured(
                    run_id=run_id, index=index, repeat=0, theta_i_deg=20.0, theta_r_deg=tr,
                    luminance_pct=gaussian_pct(tr), measured_theta_i_deg=20.0,
                    measured_theta_r_deg=tr,
                )
            )  # fmt: skip
            pub(Progress(run_id=run_id, done=index + 1, total=3, eta_s=0.0))
        pub(
            RunFinished(run_id=run_id, state=RunState.DONE, reason="", summary=dict(self.ALIGNMENT))
        )

    async def release(self, n: int) -> None:
        """Let ``n`` more points run."""
        async with self._gate:
            self._allowed += n
            self._gate.notify_all()

    def pause(self) -> None:
        self._paused = True
        self._resume.clear()

    def resume(self) -> None:
        self._paused = False
        self._resume.set()

    def abort(self) -> None:
        self._abort = True
        self._resume.set()

    async def arm_states(self) -> tuple[ArmState, ArmState]:
        ti, tr = self.position
        return (
            ArmState("lamp", ti, False, True, None, True),
            ArmState("detector", tr, False, True, None, True),
        )

    async def read_gloss(self, sample: str) -> None:
        self.gloss_samples.append(sample)
        self.publish_gloss(len(self.gloss_samples), 60.0 + len(self.gloss_samples))

    def list_runs(self) -> list[RunSummary]:
        return [s.summary for s in sorted(self.stored.values(), key=lambda r: -r.summary.run_id)]

    def load_run(self, run_id: int) -> StoredRun:
        if run_id not in self.stored:
            raise KeyError(f"no run {run_id}")
        return self.stored[run_id]

    def _ts(self, k: int) -> float:
        return T0 + k

    async def _run(self, run_id: int, setup: ScanSetup) -> None:
        pub = self.bus.publish
        thetas = setup.theta_r_values_deg()
        pub(
            RunStarted(
                run_id=run_id,
                timestamp=self._ts(0),
                kind="brdf",
                total_points=len(thetas),
                plan={"theta_i_deg": setup.theta_i_deg},
                sample=setup.sample,
            )
        )
        pub(StateChanged(run_id=run_id, timestamp=self._ts(0), state=RunState.RUNNING))
        measured: list[PointMeasured] = []
        predicted: list[PointPredicted] = []
        state = RunState.DONE
        for index, tr in enumerate(thetas):
            if self.gated:
                async with self._gate:
                    await self._gate.wait_for(lambda: self._allowed > 0)
                    self._allowed -= 1
            if self._paused:
                pub(StateChanged(run_id=run_id, timestamp=self._ts(index), state=RunState.PAUSED))
                await self._resume.wait()
                if not self._abort:
                    pub(
                        StateChanged(
                            run_id=run_id, timestamp=self._ts(index), state=RunState.RUNNING
                        )
                    )
            if self._abort:
                state = RunState.ABORTED
                break
            self.position = (setup.theta_i_deg, tr)
            pub(
                ArmsMoved(
                    run_id=run_id,
                    timestamp=self._ts(index),
                    theta_i_deg=setup.theta_i_deg,
                    theta_r_deg=tr,
                    moving=False,
                )
            )
            mean = gaussian_pct(tr)
            p = PointPredicted(
                run_id=run_id,
                timestamp=self._ts(index),
                index=index,
                theta_i_deg=setup.theta_i_deg,
                theta_r_deg=tr,
                predicted_pct=PRED_SCALE * mean,
            )
            predicted.append(p)
            pub(p)
            for rep in range(setup.repeats):
                offset = (rep - (setup.repeats - 1) / 2.0) * SPREAD_PCT
                m = PointMeasured(
                    run_id=run_id,
                    timestamp=self._ts(index),
                    index=index,
                    repeat=rep,
                    theta_i_deg=setup.theta_i_deg,
                    theta_r_deg=tr,
                    luminance_pct=mean + offset,
                    measured_theta_i_deg=setup.theta_i_deg,
                    measured_theta_r_deg=tr,
                )
                measured.append(m)
                pub(m)
            pub(
                Progress(
                    run_id=run_id,
                    timestamp=self._ts(index),
                    done=index + 1,
                    total=len(thetas),
                    eta_s=float(len(thetas) - index - 1),
                )
            )
            await asyncio.sleep(0)
        summary = {"warnings": list(self.run_warnings)} if self.run_warnings else {}
        pub(RunFinished(run_id=run_id, timestamp=self._ts(99), state=state, reason="",
                        summary=summary))  # fmt: skip
        self.stored[run_id] = StoredRun(
            RunSummary(run_id, self._ts(0), "brdf", setup.sample, state.value, len(measured)),
            measured,
            predicted,
        )

    def publish_gloss(self, k: int, g60: float) -> None:
        """A glossmeter reading (G60 only measured, all three predicted)."""
        self.bus.publish(
            GlossRead(
                run_id=0,
                timestamp=self._ts(k),
                values_gu={20: None, 60: g60, 85: None},
                predicted_gu={20: 30.0, 60: 58.0, 85: 90.0},
            )
        )

    def publish_timeout(self) -> None:
        """An instrument timeout, as the runner reports it."""
        self.bus.publish(
            InstrumentError(
                run_id=0,
                timestamp=self._ts(0),
                device="spectro",
                message="no reply to 'MEASURE' within 2.0 s",
                fatal=False,
            )
        )


async def wait_until(pilot: Pilot[int], cond: Callable[[], bool], *, max_turns: int = 1000) -> None:
    """Let the app process messages until ``cond()`` holds (no wall-clock waits)."""
    for _ in range(max_turns):
        if cond():
            return
        await pilot.pause()
    raise AssertionError("condition not reached")


async def settle(pilot: Pilot[int], app: GonioApp) -> None:
    """Wait for the rate-limited plot redraw to run and the screen to repaint."""
    await wait_until(pilot, lambda: not app.redraw_pending)
    for _ in range(3):
        await pilot.pause()
