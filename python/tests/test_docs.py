"""Every ```python block of README.md and docs/*.md runs, in a fresh interpreter.

The blocks of one guide run in order in one temporary folder that holds links to
the shared real maps by file name (``sunrise.exr``, ...), so a guide reads like a
session: a later block may read what an earlier one wrote. A block that imports
``mitsuba`` is skipped (one line) where Mitsuba or its LLVM backend is missing; a
guide that names a shared map is skipped where ``../shared/envmaps`` lacks it.
``crates/envlight-cli/tests/docs.rs`` checks that every other block has a runner.
"""

import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "envmaps"
MAPS = ["sunrise.exr", "city.exr", "night.exr", "studio.exr", "courtyard.exr", "colorful_studio_2k.hdr"]


def blocks(path):
    """(line, info, code) of each fenced block, as doc_blocks.rs reads them."""
    out, current = [], None
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        stripped = line.lstrip(" ")
        indent, ticks = len(line) - len(stripped), len(stripped) - len(stripped.lstrip("`"))
        if current is None:
            if indent <= 3 and ticks >= 3:
                current = (number, ticks, stripped[ticks:].strip(), [])
        elif indent <= 3 and ticks >= current[1] and not stripped[ticks:].strip():
            out.append((current[0], current[2], "\n".join(current[3]) + "\n"))
            current = None
        else:
            current[3].append(line)
    assert current is None, f"{path}:{current[0]}: a code fence that never closes"
    return out


def guides():
    return [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


GUIDES = [g for g in guides() if any(info == "python" for _, info, _ in blocks(g))]


def mitsuba_llvm():
    """Whether Mitsuba imports and its llvm_ad_rgb variant loads (in a child)."""
    probe = "import mitsuba as mi; mi.set_variant('llvm_ad_rgb')"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True).returncode == 0


def test_guides_have_python_blocks():
    assert GUIDES, "no guide has a ```python block: the runner found nothing"


@pytest.mark.parametrize("guide", GUIDES, ids=lambda g: str(g.relative_to(ROOT)))
def test_python_blocks_run(guide, tmp_path):
    code_blocks = [(line, code) for line, info, code in blocks(guide) if info == "python"]
    missing = [m for m in MAPS if any(m in code for _, code in code_blocks) and not (SHARED / m).is_file()]
    if missing:
        pytest.skip(f"{guide.name} reads {', '.join(missing)}, not in {SHARED}")
    for m in MAPS:
        if (SHARED / m).is_file():
            (tmp_path / m).symlink_to(SHARED / m)
    have_mitsuba = None
    for line, code in code_blocks:
        where = f"{guide.relative_to(ROOT)}:{line}"
        if "import mitsuba" in code:
            if have_mitsuba is None:
                have_mitsuba = mitsuba_llvm()
            if not have_mitsuba:
                print(f"{where}: skipped: mitsuba or its LLVM backend is missing")
                continue
        result = subprocess.run(
            [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600
        )
        assert result.returncode == 0, f"{where} failed:\n{code}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
