"""A strategy's settings dataclass is the one place of its options: defaults, checks,
the config's ``strategy.options`` and the run read it (`cgda_jax.strategies.STRATEGIES`).
"""

import dataclasses
import pathlib

import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.cli import main
from cgda_jax.experiment import load_config
from cgda_jax.experiment.config import ConfigError
from cgda_jax.experiment.rules import check_strategy_options
from cgda_jax.experiment.sections import StrategyConfig
from cgda_jax.strategies import STRATEGIES, Strategy, run, run_ie, run_trials
from cgda_jax.strategies.ie import IEPlan, IESettings
from cgda_jax.strategies.settings import Settings, option

REPO = pathlib.Path(__file__).resolve().parents[1]
CLEAN_IE = REPO / "experiments" / "clean_ie.toml"


@dataclasses.dataclass(frozen=True, kw_only=True)
class ProbeSettings(IESettings):
    """IE with one more option: the whole declaration of a new option."""

    probe: int = option(3, "int", 1)


class ProbePlan(IEPlan):
    """Where the option is used: the plan reads it from its settings."""

    def __init__(self, sim, goal, settings=None, **kw):
        super().__init__(sim, goal, ProbeSettings.of(settings), **kw)
        self.info["probe"] = self.settings.probe


@pytest.fixture
def probe(monkeypatch):
    monkeypatch.setitem(STRATEGIES, "ie", Strategy(ProbePlan, ProbeSettings))


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CGDA_JAX_CACHE", str(tmp_path_factory.mktemp("jax_cache")))


def test_a_new_option_is_its_field_and_its_use(probe, capsys):
    # its default and its check, from the field
    assert ProbeSettings().probe == 3
    with pytest.raises(ValueError, match="probe must be >= 1; got 0"):
        ProbeSettings(probe=0)
    # the config's checks of strategy.options take it from the registry
    cfg = load_config(CLEAN_IE, ["strategy.options.probe=5"])
    check_strategy_options(cfg.strategy)
    with pytest.raises(ConfigError, match=r"strategy.options.probe': must be >= 1"):
        check_strategy_options(load_config(CLEAN_IE, ["strategy.options.probe=0"]).strategy)
    # the CLI: a dry run accepts it and refuses a bad value by its key
    assert main(["run", str(CLEAN_IE), "--dry-run", "--set",
                 "strategy.options.probe=5"]) == 0
    capsys.readouterr()
    assert main(["run", str(CLEAN_IE), "--dry-run", "--set",
                 "strategy.options.probe=2.5"]) == 2
    err = capsys.readouterr().err
    assert "key 'strategy.options.probe': must be a whole number >= 1" in err
    # the run passes it to the plan
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    sim = Simulator(robot, MarkerScene(), substeps=2)
    goal = np.asarray(robot.marker_position(np.array([0.2, 0.4, 0.5], np.float32)))
    kw = dict(population_size=8, max_generations=2, restarts=0, probe=7)
    (res,) = run("ie", sim, goal[None], None, [0], batching="single", **kw)
    assert res.info["probe"] == 7
    assert run_ie(sim, goal[None], **kw).info["probe"] == 7


def test_defaults_are_the_settings():
    """The run functions, the batched trials and the config take the defaults of
    the settings dataclasses (written there only)."""
    for name, entry in STRATEGIES.items():
        assert issubclass(entry.settings, Settings)
        d = entry.settings.defaults()
        assert entry.settings() == entry.settings(**d), name
    common = Settings.defaults()
    s = StrategyConfig()
    # the config's own fields follow the common settings' defaults
    for key in ("algorithm", "population_size", "tolerance", "max_generations",
                "chunk_size"):
        assert getattr(s, key) == common[key], key
    assert IESettings().restarts == 9 and STRATEGIES["fte"].settings().population_size == 32


def test_unknown_settings_are_named():
    with pytest.raises(TypeError, match=r"unknown setting\(s\) \['bogus'\] of IESettings"):
        IESettings.of(None, bogus=1)
    with pytest.raises(ValueError, match="unknown settings \\['bogus'\\] for strategy"):
        run_trials("ie", None, None, 2, bogus=1)
    with pytest.raises(TypeError, match="settings must be IESettings"):
        IEPlan(None, np.zeros((1, 3)), STRATEGIES["fte"].settings())
