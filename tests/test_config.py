"""The config helper (datagen.config): typed loading, refusal of unknown keys, stable hashes."""

import json
import subprocess
import sys
from dataclasses import dataclass, field

import pytest
import yaml

from datagen.config import Config, stable_hash
from datagen.errors import ConfigError, DatagenError, EvalError
from datagen.eval import EvalConfig
from datagen.synth import SynthConfig
from datagen.tasks import TaskSpec, TaskTest, load_task


@dataclass(frozen=True)
class Inner(Config):
    a: float = 1.0
    pair: tuple[int, int] = (0, 1)


@dataclass(frozen=True)
class Outer(Config):
    name: str
    inner: Inner = field(default_factory=Inner)
    opt: float | None = None
    xs: tuple[float, ...] = ()
    flag: bool = False


def test_nested_dataclasses_tuples_and_numbers_are_typed():
    o = Outer.from_dict({"name": "n", "inner": {"a": 2, "pair": [3, 4]}, "xs": [1, 2.5], "opt": 3})
    assert o == Outer("n", Inner(2.0, (3, 4)), 3.0, (1.0, 2.5))
    assert isinstance(o.inner.a, float) and isinstance(o.xs, tuple)
    assert Outer.from_dict(o.to_dict()) == o
    assert o.to_dict() == {"name": "n", "inner": {"a": 2.0, "pair": [3, 4]}, "opt": 3.0, "xs": [1.0, 2.5],
                           "flag": False}
    yaml.safe_dump(o.to_dict())  # plain data: YAML-safe


@pytest.mark.parametrize("data, where", [
    ({"name": "n", "bogus": 1}, "unknown keys \\['bogus'\\]"),
    ({"name": 3}, "Outer.name: must be a string"),
    ({"name": "n", "inner": {"pair": [1, 2, 3]}}, "Outer.inner.pair"),
    ({"name": "n", "inner": {"pair": [1, 2.5]}}, "Outer.inner.pair\\[1\\]: must be an integer"),
    ({"name": "n", "inner": {"c": 1}}, "Outer.inner: unknown keys"),
    ({"name": "n", "flag": 1}, "flag: must be true or false"),
    ({"name": "n", "opt": "x"}, "opt"),
    ({"name": "n", "xs": 1.0}, "xs"),
    ({}, "missing required field\\(s\\) \\['name'\\]"),
])
def test_bad_input_names_the_field_path(data, where):
    with pytest.raises(ConfigError, match=where) as err:
        Outer.from_dict(data)
    assert isinstance(err.value, DatagenError) and isinstance(err.value, ValueError)


def test_yaml_1e4_is_a_string_and_the_remedy_says_so(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("iters: 10\nweights: {distance: 1e4}\n")
    with pytest.raises(ConfigError, match="weights.distance") as err:
        SynthConfig.from_yaml(p)
    assert "1.0e+4" in err.value.remedy
    p.write_text("iters: 10\nweights: {distance: 1.0e4}\n")  # a dot is not enough for YAML 1.1
    with pytest.raises(ConfigError, match="weights.distance"):
        SynthConfig.from_yaml(p)
    p.write_text("iters: 10\nweights: {distance: 1.0e+4}\n")  # the remedy's form is a number
    assert SynthConfig.from_yaml(p).weights.distance == 1e4
    p.write_text("iters: [10\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        SynthConfig.from_yaml(p)


def test_config_classes_use_their_own_error_class():
    with pytest.raises(EvalError, match="unknown keys"):
        EvalConfig.from_dict({"nope": 1})
    with pytest.raises(EvalError, match="tasks.x.joint: must be a string"):
        EvalConfig.from_dict({"tasks": {"x": {"w_t": [1, 0, 0, 0, 0, 0], "joint": 3}}})
    with pytest.raises(EvalError, match="w_t"):
        TaskTest.from_dict({"w_t": [1, 0, 0]})
    with pytest.raises(ConfigError, match="init.curl: must be a number"):
        TaskSpec.from_dict({"name": "t", "init": {"curl": "half"}})


def test_hash_is_stable_across_processes_and_follows_the_content():
    spec = load_task("turn_knob2")  # nested configs, tuples, floats, a free-form mapping
    code = "from datagen.tasks import load_task; print(load_task('turn_knob2').hash())"
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert other == spec.hash()
    c = SynthConfig(iters=7)
    assert SynthConfig(iters=8).hash() != c.hash()
    # the hash is that of the canonical JSON: independent of key order
    d = c.to_dict()
    assert stable_hash(dict(reversed(list(d.items())))) == c.hash()
    assert stable_hash(json.loads(json.dumps(d))) == c.hash()


def test_every_datagen_error_survives_pickling():
    """Errors cross process boundaries (Ray tasks, evaluation pools): each subclass, whatever its
    constructor's signature, comes back with its type, message and attributes (an EvalError
    that could not be unpickled once hung a process pool's result thread)."""
    import pickle

    from datagen.errors import ConfigError, EvalError
    from datagen.hands.spec import HandSpecError
    from datagen.objects.errors import MeshProcessingError, Reason
    from workers.job import JobConfigError

    made = [EvalError("object 'a'", "cannot read it", "run datagen prepare"),
            ConfigError.make("SynthConfig.iters", "must be > 0"),
            JobConfigError.make("JobConfig.count", "must be >= 1"),
            HandSpecError("spec.yaml", "malformed", "fix it"),
            MeshProcessingError(Reason.COACD_FAILED, "mesh.obj", "CoACD raised"),
            ]
    for exc in made:
        back = pickle.loads(pickle.dumps(exc))
        assert type(back) is type(exc) and str(back) == str(exc) and back.__dict__ == exc.__dict__, exc


def test_a_key_given_twice_is_refused_not_last_wins(tmp_path):
    from datagen.config import read_yaml
    from datagen.synth import SynthConfig

    p = tmp_path / "c.yaml"
    for text, where in (("iters: 10\niters: 20\n", "lines 1 and 2"), ("weights: {distance: 1, distance: 2}\n",
                                                                        "lines 1 and 1")):
        p.write_text(text)
        with pytest.raises(ValueError, match=rf"c.yaml: the config is not plain YAML data: key '\w+' given twice "
                                             rf"\({where}\): remove one"):
            read_yaml(p)
        with pytest.raises(ConfigError, match="given twice"):
            SynthConfig.from_yaml(p)
    p.write_text("a: {x: 1}\nb: {x: 2}\n")  # the same key in two mappings is fine
    assert read_yaml(p) == {"a": {"x": 1}, "b": {"x": 2}}
