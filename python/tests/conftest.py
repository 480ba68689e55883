"""Fixtures shared by the pytest suite."""

import pathlib
import shutil

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture
def envlight_cli():
    """The path of the `envlight` binary (on PATH, or built in this checkout);
    skips the test when there is none."""
    found = shutil.which("envlight")
    if found:
        return found
    for profile in ("release", "debug"):
        p = ROOT / "target" / profile / "envlight"
        if p.exists():
            return str(p)
    pytest.skip("the envlight binary is not built (cargo build --release)")


def pytest_terminal_summary(terminalreporter):
    """One line per reason the Mitsuba tests were skipped (Mitsuba not installed, no
    LLVM for its JIT variants), so that a skip is visible without -rs."""
    reasons = []
    for report in terminalreporter.stats.get("skipped", []):
        longrepr = report.longrepr
        reason = longrepr[2] if isinstance(longrepr, tuple) and len(longrepr) == 3 else str(longrepr)
        reason = reason.removeprefix("Skipped: ")
        if ("mitsuba" in reason.lower() or "llvm" in reason.lower()) and reason not in reasons:
            reasons.append(reason)
    for reason in reasons:
        terminalreporter.write_line(f"envlight.mitsuba: skipped: {reason}")
