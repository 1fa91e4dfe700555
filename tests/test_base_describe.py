"""`dpc-mjx base FILE` (`dpc_mjx.robots.bases.describe`): what `read_base` inferred, as text, and
the JSON file that reproduces it. MuJoCo C and numpy only: nothing here compiles a JAX program."""

import json

import numpy as np
import pytest

from dpc_mjx import DpcError
from dpc_mjx.robots.bases.describe import describe, description
from dpc_mjx.robots.bases.file import LEGS, NAMED_BASES, BaseSpec, base_file_path, read_base
from dpc_mjx.run import cli
from dpc_mjx.serialization import write_json

_EXACT = 1e-9  # rad, m: a base read back from its JSON vs the base it was written from


def _round_trip(spec: BaseSpec, path) -> BaseSpec:
    """`spec` written as its JSON at `path` and read back."""
    write_json(path, description(spec, path))
    back = read_base(path)
    assert back.leg_joints == spec.leg_joints
    np.testing.assert_allclose(back.home_qpos, spec.home_qpos, rtol=0, atol=_EXACT)
    assert back.home_height == pytest.approx(spec.home_height, abs=_EXACT)
    assert back.foot_radius == pytest.approx(spec.foot_radius, abs=_EXACT)
    assert back.trunk == spec.trunk and back.mass == pytest.approx(spec.mass)
    return back


@pytest.mark.parametrize("name", NAMED_BASES)
def test_the_json_of_every_named_base_reads_back_as_the_base(tmp_path, name):
    spec = read_base(name)
    back = _round_trip(spec, tmp_path / f"{name}.json")
    assert back.home_from == "given"
    assert json.loads((tmp_path / f"{name}.json").read_text())["file"] == str(spec.path)


def test_a_given_home_height_reads_back(tmp_path):
    spec = read_base("a1", home_height=0.25)
    assert _round_trip(spec, tmp_path / "low.json").home_height == 0.25


def test_legs_named_by_hand_read_back_and_the_urdf_beside_the_json_is_relative(tmp_path):
    text = base_file_path("a1").read_text()
    swapped = text.replace("FR_", "XX_").replace("RL_", "FR_").replace("XX_", "RL_")
    (tmp_path / "my_dog.urdf").write_text(swapped)
    legs = {"FR": "RL_hip_joint", "FL": "FL_hip_joint", "RR": "RR_hip_joint", "RL": "FR_hip_joint"}
    spec = read_base(tmp_path / "my_dog.urdf", legs=legs)
    out = description(spec, tmp_path / "my_dog.json")
    assert out["file"] == "my_dog.urdf" and out["legs"] == legs
    _round_trip(spec, tmp_path / "my_dog.json")
    assert _round_trip(spec, tmp_path / "sub" / "my_dog.json").path == spec.path  # absolute


def test_describe_names_every_leg_its_joints_and_the_masses():
    spec = read_base("b1-z1")
    text = describe(spec)
    for leg in spec.legs:
        assert f"{leg.place}: joints {', '.join(leg.joints)}" in text
        assert leg.foot in text
    assert f"{spec.mass:.4f} kg" in text and f"{spec.base_mass:.4f} kg" in text
    assert f"{spec.home_height:.4f} m" in text and spec.home_from in text
    assert spec.others[0].root in text and "jointGripper" in text


def test_cli_prints_the_base_and_writes_its_json(tmp_path, capsys):
    path = tmp_path / "go2.json"
    assert cli.main(["base", "go2", "--out", str(path)]) == 0
    printed = capsys.readouterr().out
    assert all(f"{place}: joints {place}_hip_joint" in printed for place in LEGS)
    assert str(path) in printed
    written = json.loads(path.read_text())
    assert written["legs"] == {place: f"{place}_hip_joint" for place in LEGS}
    assert written["home_height"] == read_base("go2").home_height


def test_cli_without_out_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["base", "a1"]) == 0
    assert "FR: joints FR_hip_joint" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []


def test_a_missing_file_is_named(tmp_path, capsys):
    missing = tmp_path / "no_dog.urdf"
    with pytest.raises(DpcError, match="does not exist"):
        read_base(missing)
    assert cli.main(["base", str(missing), "--out", str(tmp_path / "x.json")]) == 2
    assert "no_dog.urdf" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()
