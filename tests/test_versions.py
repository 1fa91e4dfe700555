"""The declared version ranges (pyproject.toml), the pinned set (constraints.txt) and what is
installed agree with each other (docs/decisions.md, "Packaging and versions")."""

import re
import sys
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

from dpc_mjx.run import cli

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
# Releases inside a range's bounds that it excludes: (package, release, why), read from their
# changelogs.
_EXCLUDED = (
    (
        "mujoco", "4.0.0",
        "its sparse Cholesky factorisation (new in 4.0.0) merged rows with different descendants "
        "into one supernode, giving the Newton solver a wrong Hessian factor: wrong accelerations "
        "and divergence when the constraint Jacobian is sparse (fixed in 4.0.1, MuJoCo issue 3767)",
    ),
)  # fmt: skip
# The MuJoCo that `make test-mujoco3` puts in place of the pinned one (Makefile, MUJOCO3)
_MAKEFILE_MUJOCO = re.compile(r"^MUJOCO3 := (\S+)$", re.MULTILINE)


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


def test_mjx_is_3_17_beside_a_mujoco_no_older():
    """mujoco-mjx has no 4.x: its 3.17 (which asks for mujoco >= 3.17.0.dev0) runs on MuJoCo 3.17
    and on 4.0.1 (the suite on both: `make test`, `make test-mujoco3`)."""
    mjx, mj = Version(version("mujoco-mjx")), Version(version("mujoco"))
    assert mjx.release[:2] == (3, 17), f"mujoco-mjx {mjx}: the tested releases are 3.17.*"
    assert mj >= mjx, f"mujoco {mj} is older than mujoco-mjx {mjx}, which needs mujoco >= 3.17"


@pytest.mark.parametrize("python", PYTHONS)
def test_the_ranges_exclude_the_releases_known_broken(python):
    core, _ = _declared(python)
    for name, release, why in _EXCLUDED:
        assert not core[name].specifier.contains(release, prereleases=True), (
            f"{core[name]} admits {name} {release}: {why}"
        )


def test_the_makefiles_other_mujoco_lies_in_the_range():
    (other,) = _MAKEFILE_MUJOCO.findall((ROOT / "Makefile").read_text())
    assert _declared()[0]["mujoco"].specifier.contains(other), f"Makefile's MUJOCO3 {other}"
    assert other != _pins()["mujoco"], "make test-mujoco3 would test the pinned MuJoCo again"


class _HalfInstalledMujoco:
    """A finder whose `import mujoco` fails as MuJoCo 4's does after `pip install -U` over 3.x."""

    def find_spec(self, name, path=None, target=None):
        if name == "mujoco":
            raise ImportError(
                "The 'mujoco' package is installed, but its core bindings ('mujoco-core') are "
                "missing or corrupted (for example, after uninstalling a previous monolithic "
                "'mujoco' package). Repair your environment with:\n  pip install "
                "--force-reinstall --no-deps mujoco mujoco-core mujoco-studio"
            )


def test_cli_names_the_repair_of_a_half_installed_mujoco_in_one_line(monkeypatch, capsys):
    monkeypatch.delitem(sys.modules, "mujoco", raising=False)
    monkeypatch.setattr(sys, "meta_path", [_HalfInstalledMujoco(), *sys.meta_path])
    assert cli.main(["variants"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("dpc-mjx: error: MuJoCo ") and "half-installed" in line, line
    assert line.endswith(
        f"pip uninstall -y mujoco mujoco-core mujoco-studio && pip install "
        f"mujoco=={version('mujoco')}"
    ), line


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
