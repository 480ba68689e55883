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
