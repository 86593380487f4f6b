"""The instrument protocol tables (drivers/protocols.py) are what the config validation, the
CLI choices, the driver construction and docs/ARCHITECTURE.md read.

The toy protocol is the worked example of docs/ARCHITECTURE.md ("Adding an instrument
protocol"), run from the doc itself: its module and its registration, nothing else.
"""

from __future__ import annotations

import re
import sys
import types
from collections.abc import Iterator
from pathlib import Path

import pytest

import drivers.protocols as protocols
from drivers.glossmeter import LineGlossmeter, Zgm1120, open_glossmeter
from drivers.protocols import GLOSSMETERS, SPECTROS, STEPPERS, TABLES, ProtocolEntry
from goniolab.config import ConfigError, LabConfig, load_lab_config

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "ARCHITECTURE.md"


def doc_block(name: str) -> str:
    """The fenced code block after ``<!-- example: NAME -->`` in docs/ARCHITECTURE.md."""
    text = DOC.read_text(encoding="utf-8")
    m = re.search(rf"<!-- example: {name} -->\s*```python\n(.*?)```", text, re.S)
    assert m, f"docs/ARCHITECTURE.md has no example block {name!r}"
    return m.group(1)


@pytest.fixture
def acme(monkeypatch: pytest.MonkeyPatch) -> Iterator[ProtocolEntry]:
    """The doc's ACME module as ``drivers.acme_gloss`` and its registration run."""
    module = types.ModuleType("drivers.acme_gloss")
    exec(compile(doc_block("acme-module"), "drivers/acme_gloss.py", "exec"), module.__dict__)
    monkeypatch.setitem(sys.modules, "drivers.acme_gloss", module)
    assert "acme" not in GLOSSMETERS
    namespace = dict(vars(protocols))
    try:
        exec(compile(doc_block("acme-registration"), "drivers/protocols.py", "exec"), namespace)
        yield GLOSSMETERS["acme"]
    finally:
        GLOSSMETERS.unregister("acme")
    assert "acme" not in GLOSSMETERS


def gloss_log_protocol_choices() -> tuple[str, ...]:
    from goniolab.cli import build_parser

    parser = build_parser()
    top = parser._subparsers._group_actions[0]  # type: ignore[union-attr]
    gloss = top.choices["gloss"]
    log = gloss._subparsers._group_actions[0].choices["log"]  # type: ignore[union-attr]
    (action,) = [a for a in log._actions if a.dest == "protocol"]
    assert action.choices is not None
    return tuple(action.choices)


def write_config(tmp_path: Path, glossmeter: str) -> Path:
    path = tmp_path / "lab.toml"
    path.write_text(f"[lab]\nmode = 'drivers'\n\n[glossmeter]\n{glossmeter}\n", encoding="utf-8")
    return path


def test_builtin_protocols() -> None:
    assert STEPPERS.names() == ("modbus",)
    assert SPECTROS.names() == ("stil",)
    assert GLOSSMETERS.names() == ("zgm1120", "line")
    assert gloss_log_protocol_choices() == ("zgm1120", "line")


def test_the_toy_protocol_reaches_the_cli(acme: ProtocolEntry) -> None:
    assert gloss_log_protocol_choices() == ("zgm1120", "line", "acme")


def test_the_toy_protocol_passes_config_validation(tmp_path: Path, acme: ProtocolEntry) -> None:
    cfg = load_lab_config(write_config(tmp_path, 'protocol = "acme"'))
    assert cfg.glossmeter.protocol == "acme"
    # no profile given: the entry's default, resolved to its file
    assert Path(cfg.glossmeter.profile).name == "line-gloss-example.toml"


def test_the_toy_protocol_refuses_another_kind_of_profile(
    tmp_path: Path, acme: ProtocolEntry
) -> None:
    path = write_config(tmp_path, 'protocol = "acme"\nprofile = "zgm1120"')
    with pytest.raises(ConfigError) as info:
        load_lab_config(path)
    assert info.value.key == "glossmeter.profile"
    assert "is not a 'line-gloss' profile" in info.value.reason


def test_an_unregistered_protocol_is_refused_naming_the_known_ones(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load_lab_config(write_config(tmp_path, 'protocol = "acme"'))
    assert info.value.key == "glossmeter.protocol"
    assert "unknown glossmeter protocol 'acme' (known: 'zgm1120', 'line')" in info.value.reason


def test_the_toy_protocol_builds_its_driver(acme: ProtocolEntry) -> None:
    meter = open_glossmeter("/dev/x", protocol="acme", timeout_s=0.5)
    assert type(meter).__name__ == "AcmeGlossmeter" and isinstance(meter, LineGlossmeter)
    assert meter.profile.name == "line-gloss-example" and meter.timeout_s == 0.5
    zgm = open_glossmeter("/dev/x", serial_number="123")  # the options reach the ZGM1120 only
    assert isinstance(zgm, Zgm1120) and zgm.serial_number == "123"


def test_the_wire_twin_refuses_a_protocol_it_does_not_serve(acme: ProtocolEntry) -> None:
    from drivers.timing import SimClock
    from goniolab.lab_wiring import build_sim_instruments, build_sim_server
    from goniolab.optics.analytic import AnalyticModel

    cfg = LabConfig.model_validate(
        {"glossmeter": {"protocol": "acme"}, "sim": {"twin": {"mode": "ideal"}}}
    )
    sims = build_sim_instruments(cfg, AnalyticModel("ggx", alpha=0.08, n=1.55), SimClock(0.0))
    with pytest.raises(ConfigError) as info:
        build_sim_server(cfg, sims)
    assert info.value.key == "glossmeter.protocol"
    assert 'serves the "zgm1120" protocol only' in info.value.reason


def test_registering_twice_or_in_the_wrong_table_is_refused(acme: ProtocolEntry) -> None:
    with pytest.raises(ValueError, match="already registered"):
        GLOSSMETERS.register(acme)
    with pytest.raises(ValueError, match="cannot go in the spectro table"):
        SPECTROS.register(acme)


def protocol_table_markdown() -> str:
    import sim.assembly  # noqa: F401 -- the twin registers the protocols it serves

    rows = [
        "| device | protocol | profile kind | default profile | driver | wire twin | description |",
        "|---|---|---|---|---|---|---|",
    ]
    for device, table in TABLES.items():
        for e in table.entries():
            served = "yes" if table.simulator(e.name) is not None else "no"
            rows.append(
                f"| {device} | `{e.name}` | `{e.profile_kind}` | `{e.default_profile}` "
                f"| `{e.driver}` | {served} | {e.description} |"
            )
    return "\n".join(rows)


def test_the_docs_list_the_registered_protocols() -> None:
    text = DOC.read_text(encoding="utf-8")
    m = re.search(r"<!-- protocols:begin -->\n(.*?)\n?<!-- protocols:end -->", text, re.S)
    assert m, "docs/ARCHITECTURE.md lacks the protocols:begin/end markers"
    expected = protocol_table_markdown()
    assert m.group(1).strip() == expected, f"paste into docs/ARCHITECTURE.md:\n{expected}"


async def test_the_lab_builds_and_connects_the_toy_driver(
    tmp_path: Path, acme: ProtocolEntry
) -> None:
    """A lab config naming the toy protocol gets its driver: connecting it sends the
    doc's WAKE line (with the line-gloss-example profile's CRLF) down the port."""
    import os
    import select
    import tty

    from goniolab.lab_wiring import Lab
    from goniolab.optics.analytic import AnalyticModel

    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        path = write_config(tmp_path, f'protocol = "acme"\nport = "{os.ttyname(slave)}"')
        lab = Lab.from_config(
            path, model=AnalyticModel("ggx", alpha=0.08, n=1.55), instruments=("glossmeter",)
        )
        async with lab:
            assert type(lab.glossmeter).__name__ == "AcmeGlossmeter"
            ready, _, _ = select.select([master], [], [], 5.0)
            assert ready, "the driver wrote nothing within 5 s"
            assert os.read(master, 64) == b"WAKE\r\n"
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize(
    ("table", "key", "known"),
    [
        ("goniometer.lamp", "goniometer.lamp.protocol", "'modbus'"),
        ("spectro", "spectro.protocol", "'stil'"),
        ("glossmeter", "glossmeter.protocol", "'zgm1120', 'line'"),
    ],
)
def test_every_device_protocol_is_checked_against_its_table(
    tmp_path: Path, table: str, key: str, known: str
) -> None:
    path = tmp_path / "lab.toml"
    path.write_text(f'[{table}]\nprotocol = "nope"\n', encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_lab_config(path)
    assert info.value.key == key
    assert info.value.reason.endswith(f"protocol 'nope' (known: {known})")
