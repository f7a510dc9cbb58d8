"""Fault injection: every case expects ONE line naming the file or key and the fix.

`fault(ExcType, *needles)` is a context manager: the block must raise ExcType (SystemExit for an
app) with a one-line message holding every needle. The message is recorded under the test's name;
the table in docs/DEVELOPING.md ("Fault cases") is generated from these records:
    PALPATION_FAULTS_TABLE=write python -m pytest -q tests/faults   # rewrite the table
When the whole folder runs, a table that differs from the docs fails the session (it cannot drift).
"""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path

import pytest

from palpation.paths import REPO_ROOT

DOC = Path(__file__).resolve().parents[2] / "docs" / "DEVELOPING.md"
START, END = "<!-- fault-cases:start -->", "<!-- fault-cases:end -->"
MESSAGES: dict[str, tuple[str, str]] = {}  # test name -> (what it injects, message)


@pytest.fixture(autouse=True)
def _record_behaviour(request):
    """Cases that expect no error (a stale file ignored, bytes identical) are listed too, by docstring."""
    yield
    doc = (request.node.function.__doc__ or "").strip()
    if doc and request.node.name not in MESSAGES:
        MESSAGES[request.node.name] = (doc.splitlines()[0], "(no error: checked by the test)")


@pytest.fixture
def fault(request, tmp_path):
    @contextlib.contextmanager
    def expect(exc_type, *needles):
        with pytest.raises(exc_type) as info:
            yield info
        exc = info.value
        msg = str(exc.code if isinstance(exc, SystemExit) else exc)
        assert "\n" not in msg.strip(), f"not one line: {msg!r}"
        assert "Traceback" not in msg
        for needle in needles:
            assert needle in msg, f"{needle!r} not in {msg!r}"
        doc = (request.node.function.__doc__ or request.node.name).strip().splitlines()[0]
        MESSAGES[request.node.name] = (doc, re.sub(re.escape(str(tmp_path)) + r"|/tmp/[\w./-]*pytest-\d+/[\w-]+",
                                                   "<tmp>", msg))
    return expect


def table() -> str:
    rows = ["| case | fault injected | message |", "|---|---|---|"]
    for name in sorted(MESSAGES):
        doc, msg = MESSAGES[name]
        rows.append(f"| `{name}` | {doc} | {msg.replace('|', '/')} |")
    return "\n".join(rows)


def documented() -> str:
    text = DOC.read_text()
    return text[text.index(START) + len(START):text.index(END)].strip() if START in text else ""


@pytest.fixture
def hydra_job():
    """compose(app, overrides) as a Hydra job sees it (HydraConfig set, overrides recorded)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import open_dict

    import palpation.calibration.config  # noqa: F401  (registers the structured configs)
    import palpation.loop.config  # noqa: F401
    import palpation.mapping.config  # noqa: F401  (base_vessel_maps)
    import palpation.model.config  # noqa: F401  (base_train; the folder alone failed without it)
    import palpation.twin.config  # noqa: F401

    def make(app: str, overrides=()):
        cfg = compose(app, overrides=list(overrides), return_hydra_config=True)
        HydraConfig.instance().set_config(cfg)
        with open_dict(cfg):
            del cfg["hydra"]
        return cfg

    with initialize_config_dir(str(REPO_ROOT / "conf"), version_base="1.3"):
        yield make
    HydraConfig.instance().cfg = None


DESELECTED: list = []


def _here(item) -> bool:
    return Path(str(item.fspath)).parent == Path(__file__).parent


def pytest_deselected(items):
    DESELECTED.extend(i for i in items if _here(i))


def pytest_sessionfinish(session, exitstatus):
    files = {Path(str(i.fspath)).name for i in session.items if _here(i)}
    every = {p.name for p in Path(__file__).parent.glob("test_*.py")}
    ran_all = files == every and not DESELECTED and exitstatus == 0
    if not MESSAGES or not ran_all:
        return
    if os.environ.get("PALPATION_FAULTS_TABLE") == "write":
        text = DOC.read_text()
        head, tail = text.split(START)[0], text.split(END)[1]
        DOC.write_text(f"{head}{START}\n{table()}\n{END}{tail}")
    elif documented() != table():
        print(f"\nthe fault-case table of {DOC} is out of date: PALPATION_FAULTS_TABLE=write "
              "python -m pytest -q tests/faults")
        session.exitstatus = 1
