"""The layers section of docs/architecture.md (the README points there) matches the code: every
file it names exists, and every module of the library is named there."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dpc_mjx"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
SECTION = "## The layers"  # its section drawing the layers and the path of a step


def _architecture() -> str:
    """The section, from its heading to the next one of its level."""
    text = ARCHITECTURE.read_text()
    start = text.index(SECTION)
    return text[start : text.index("\n## ", start + 1)]


def test_every_file_the_architecture_names_exists():
    section = _architecture()
    modules = {p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")}
    named = set(re.findall(r"(?:[a-z_]+/)*[a-z_0-9]+\.py", section))
    assert named, f"{SECTION} of docs/architecture.md names no file"
    missing = sorted(n for n in named if not any(m == n or m.endswith("/" + n) for m in modules))
    assert not missing, f"docs/architecture.md ({SECTION}) names files that do not exist: {missing}"


def test_every_module_is_named_in_the_architecture():
    words = set(re.findall(r"[a-z_0-9]+", _architecture()))
    unnamed = sorted(
        p.relative_to(PACKAGE).as_posix()
        for p in PACKAGE.rglob("*.py")
        if p.stem != "__init__" and p.stem not in words
    )
    assert not unnamed, f"modules missing from docs/architecture.md ({SECTION}): {unnamed}"
