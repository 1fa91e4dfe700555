"""One name per controller (`dpc_mjx.controllers.Controller`), read the same way by envs, the
evaluation, the closed-loop bench, deployment and the command line (no compiling)."""

import pytest

from dpc_mjx import DpcError
from dpc_mjx.control.closed_loop import CONTROLLERS as BENCH_CONTROLLERS
from dpc_mjx.control.closed_loop import GIVEN
from dpc_mjx.controllers import ALIASES, Controller
from dpc_mjx.envs import CONTROLLERS as ENV_CONTROLLERS
from dpc_mjx.envs import DEFAULT_TASK, EnvConfig, get_config
from dpc_mjx.io.load import load
from dpc_mjx.io.shipped import SHIPPED_PAPER, env_overrides
from dpc_mjx.run import cli
from dpc_mjx.run.config import RunConfig
from dpc_mjx.run.eval import CONTROLLERS as EVAL_CONTROLLERS
from dpc_mjx.run.eval import evaluate


def test_members_are_the_strings_of_before_in_the_tables_order():
    assert [c.value for c in Controller] == [
        *("mbc", "observer", "feedforward", "feedforward_observer", "dpc", "oracle")
    ]
    assert (
        Controller.DPC == "dpc" and "mbc" == Controller.MBC and f"{Controller.ORACLE}" == "oracle"
    )
    assert {"dpc": 1}[Controller.DPC] == 1  # a member finds a plain string's key
    assert EVAL_CONTROLLERS == ENV_CONTROLLERS == tuple(Controller) == RunConfig().eval_controllers


def test_what_the_low_level_controller_adds_to_each_controllers_u():
    """(the observer's estimate, the arms' model wrench): the classical controllers by name,
    DPC by its u_base; the oracle and MBC nothing."""
    adds = {c: c.adds() for c in Controller}
    assert adds == {
        Controller.MBC: (False, False),
        Controller.OBSERVER: (True, False),
        Controller.FEEDFORWARD: (False, True),
        Controller.FEEDFORWARD_OBSERVER: (True, True),
        Controller.DPC: (False, False),
        Controller.ORACLE: (False, False),
    }
    bases = {b: Controller.DPC.adds(b) for b in ("zero", "observer", "gravity", "model")}
    assert bases == {
        "zero": (False, False),
        "observer": (True, False),
        "gravity": (False, False),
        "model": (False, True),
    }
    assert Controller.MBC.adds("model") == (False, False)  # u_base is DPC's alone


def test_parse_takes_members_strings_and_the_policy_alias():
    assert Controller.parse("observer") is Controller.OBSERVER
    assert Controller.parse(Controller.MBC) is Controller.MBC
    assert Controller.parse("policy") is Controller.DPC is Controller("policy")
    assert ALIASES == {"policy": Controller.DPC}
    assert Controller.parse_all(["mbc", "policy", "oracle"]) == (
        Controller.MBC,
        Controller.DPC,
        Controller.ORACLE,
    )


@pytest.mark.parametrize("bad", ["pid", "DPC", "", None, 3])
def test_parse_names_the_valid_controllers_otherwise(bad):
    with pytest.raises(
        DpcError,
        match=r"Unknown controller .*\['mbc', 'observer', 'feedforward', "
        r"'feedforward_observer', 'dpc', 'oracle'\]",
    ):
        Controller.parse(bad)


def test_env_config_reads_policy_as_dpc_and_old_sidecars_still_load():
    """The env's 'policy' (its name for DPC before the enum) is DPC; an export written before
    (its env_config says 'policy') loads and is evaluated under the same env options."""
    assert EnvConfig().controller is Controller.DPC
    assert EnvConfig(controller="policy") == EnvConfig(controller="dpc") == EnvConfig()
    assert get_config(DEFAULT_TASK, controller="policy").controller is Controller.DPC
    assert get_config(DEFAULT_TASK, controller="mbc").controller is Controller.MBC
    with pytest.raises(DpcError, match="Unknown controller 'pid'"):
        get_config(DEFAULT_TASK, controller="pid")
    art = load(SHIPPED_PAPER)
    assert art.meta["env_config"]["controller"] == "policy"  # written before the enum
    assert "controller" not in env_overrides(art)  # chosen per use, as before
    get_config(DEFAULT_TASK, **art.meta["env_config"])  # and still a valid env config


def test_the_closed_loop_bench_takes_the_controllers_but_dpc_and_given():
    assert BENCH_CONTROLLERS == ("mbc", "oracle", "observer", "given") and GIVEN == "given"
    assert Controller.DPC not in BENCH_CONTROLLERS


def test_evaluate_refuses_unknown_controllers_before_building_anything():
    with pytest.raises(DpcError, match="Unknown controller 'pid'"):
        evaluate(["regular"], ["mbc", "pid"])
    with pytest.raises(DpcError, match="needs a trained policy"):
        evaluate(["regular"], ["policy"])  # 'policy' is DPC: it needs the policy


def test_the_command_line_offers_the_same_names():
    args = cli._parser().parse_args(["eval"])
    assert args.controllers == [c.value for c in Controller] and args.task is None
    assert cli._parser().parse_args(["render", "--out", "x.mp4"]).controller == "mbc"
