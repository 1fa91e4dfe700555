"""The declared version ranges (pyproject.toml), the pinned set (constraints.txt) and what is
installed agree with each other (docs/decisions.md, "Packaging and versions")."""

import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]


def _by_name(requirements: list[str]) -> dict[str, Requirement]:
    return {canonicalize_name(Requirement(r).name): Requirement(r) for r in requirements}


def _declared() -> tuple[dict[str, Requirement], dict[str, Requirement]]:
    """({name: requirement} of the core dependencies, {name: requirement} of every extra)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = [r for reqs in project["optional-dependencies"].values() for r in reqs]
    return _by_name(project["dependencies"]), _by_name(extras)


def _pins() -> dict[str, str]:
    """{name: version} from the `name==version` lines of constraints.txt."""
    pins = {}
    for raw in (ROOT / "constraints.txt").read_text().splitlines():
        line = raw.split("#")[0].strip()
        if not line:
            continue
        req = Requirement(line)
        (spec,) = req.specifier  # one exact pin per line
        assert spec.operator == "==", f"constraints.txt pins exactly, not {line!r}"
        pins[canonicalize_name(req.name)] = spec.version
    return pins


def test_every_pin_lies_in_the_declared_range():
    core, extras = _declared()
    declared = {**extras, **core}
    for name, pinned in _pins().items():
        assert name in declared, f"{name} is pinned in constraints.txt but not declared"
        assert declared[name].specifier.contains(pinned, prereleases=True), (
            f"{name}=={pinned} (constraints.txt) is outside {declared[name]} (pyproject.toml)"
        )


def test_every_declared_package_is_pinned():
    core, extras = _declared()
    missing = sorted((set(core) | set(extras)) - set(_pins()))
    assert not missing, f"declared in pyproject.toml but not pinned in constraints.txt: {missing}"


@pytest.mark.parametrize("name", sorted(_declared()[0]))
def test_installed_core_dependency_lies_in_the_declared_range(name):
    installed = version(name)
    requirement = _declared()[0][name]
    assert requirement.specifier.contains(installed, prereleases=True), (
        f"installed {name} {installed} is outside the supported {requirement}"
    )


def test_mujoco_and_mjx_are_the_same_release():
    assert version("mujoco") == version("mujoco-mjx")
