"""The declared version ranges (pyproject.toml), the pinned set (constraints.txt) and what is
installed agree with each other (docs/decisions.md, "Packaging and versions")."""

import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]

# Pairs that install together but cannot run: (package, its first release that runs beside
# `other` from `other_from` on, other, other_from, the first Python `other_from` installs on, why),
# read from the packages' sources and metadata.
_NEEDED_TOGETHER = (
    (
        "flax", "0.12.7", "jax", "0.11.0", "3.12",
        "flax <= 0.12.6 calls jax.core.get_opaque_trace_state and subclasses jax.core.Effect, "
        "both removed in jax 0.11.0; flax 0.12.7 calls neither (and asks for jax >= 0.10)",
    ),
)  # fmt: skip
PYTHONS = ("3.11", "3.12", "3.13", "3.14")  # requires-python >= 3.11


def _applies(requirement: Requirement, python: str | None) -> bool:
    """Whether a requirement's marker holds on `python` (None: this interpreter)."""
    if requirement.marker is None:
        return True
    return requirement.marker.evaluate(None if python is None else {"python_version": python})


def _by_name(requirements: list[str], python: str | None = None) -> dict[str, Requirement]:
    """{name: requirement} of those that apply on `python` (None: this interpreter)."""
    reqs = [Requirement(r) for r in requirements]
    return {canonicalize_name(r.name): r for r in reqs if _applies(r, python)}


def _declared(python: str | None = None) -> tuple[dict[str, Requirement], dict]:
    """({name: requirement} of the core dependencies, {name: requirement} of every extra), on
    `python` (None: this interpreter)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = [r for reqs in project["optional-dependencies"].values() for r in reqs]
    return _by_name(project["dependencies"], python), _by_name(extras, python)


def _pins(python: str | None = None) -> dict[str, str]:
    """{name: version} from the `name==version` lines of constraints.txt that apply on
    `python` (None: this interpreter)."""
    pins = {}
    for raw in (ROOT / "constraints.txt").read_text().splitlines():
        line = raw.split("#")[0].strip()
        if not line:
            continue
        req = Requirement(line)
        (spec,) = req.specifier  # one exact pin per line
        assert spec.operator == "==", f"constraints.txt pins exactly, not {line!r}"
        if _applies(req, python):
            pins[canonicalize_name(req.name)] = spec.version
    return pins


@pytest.mark.parametrize("python", PYTHONS)
def test_every_pin_lies_in_the_declared_range(python):
    core, extras = _declared(python)
    declared = {**extras, **core}
    for name, pinned in _pins(python).items():
        assert name in declared, f"{name} is pinned in constraints.txt but not declared"
        assert declared[name].specifier.contains(pinned, prereleases=True), (
            f"{name}=={pinned} (constraints.txt, Python {python}) is outside {declared[name]}"
        )


@pytest.mark.parametrize("python", PYTHONS)
def test_every_declared_package_is_pinned(python):
    core, extras = _declared(python)
    missing = sorted((set(core) | set(extras)) - set(_pins(python)))
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


@pytest.mark.parametrize("python", PYTHONS)
def test_the_ranges_admit_no_pair_known_not_to_run(python):
    core, _ = _declared(python)
    for name, first, other, other_from, needs_python, why in _NEEDED_TOGETHER:
        if Version(python) < Version(needs_python) or not core[other].specifier.contains(
            other_from
        ):
            continue  # `other` cannot reach the release that needs `first` here
        floors = [Version(s.version) for s in core[name].specifier if s.operator in (">=", "==")]
        assert any(f >= Version(first) for f in floors), (
            f"{core[name]} admits {name} < {first} beside {other} >= {other_from} on Python "
            f"{python}: {why}"
        )
