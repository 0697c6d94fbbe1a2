"""One configuration: the resolver's layers and the entry points that share it.

Checked: the order library defaults -> preset -> task YAML -> config -> flags, with a layer's key
winning even when it equals a default (``--seeds 1`` on a task whose block sets 16; a config
setting a task's option back to the default); nested mappings merged key by key; the evaluation's
actuator gain is the squeeze's; bad input named. Then the library call with its defaults,
``datagen synth`` + ``datagen eval`` and a one-object job give the same grasps for the same seed.
"""

from __future__ import annotations

import math

import pyarrow.parquet as pq
import pytest
import trimesh
import yaml

from datagen.errors import ConfigError
from datagen.pipeline import PRESETS, resolve
from datagen.synth import SynthConfig
from datagen.tasks import load_task
from datagen.tasks.spec import builtin_tasks


def test_layers_stack_in_order_and_a_set_key_wins_even_at_its_default():
    key = load_task("precision_key")
    assert key.synth["seeds_per_grasp"] == 16 and key.synth["exact_contacts"] is True
    r = resolve("shadow", "precision_key")  # dataset preset, then the task's block
    assert (r.synth.iters, r.synth.seeds_per_grasp, r.synth.exact_contacts) == (300, 16, True)
    assert r.synth.pinch_antipodal == 1.0 and r.synth.task == "precision_key"
    # flags over the task: one seed, although 1 is SynthConfig's own default
    assert resolve("shadow", "precision_key", flags={"synth": {"seeds_per_grasp": 1}}).synth.seeds_per_grasp == 1
    # a config sets a task's option back to the library default
    back = resolve("shadow", "precision_key", config={"synth": {"exact_contacts": False}})
    assert back.synth.exact_contacts is False and back.synth.seeds_per_grasp == 16
    # flags over the config, the config over the preset
    both = resolve("shadow", "force_closure", config={"synth": {"iters": 40, "seed": 2}}, flags={"synth": {"iters": 7}})
    assert (both.synth.iters, both.synth.seed, both.synth.seeds_per_grasp) == (7, 2, 16)


@pytest.mark.parametrize("task", builtin_tasks())
def test_one_seed_and_a_tasks_option_set_back_to_the_default_are_honoured_on_every_task(task):
    """``--seeds 1`` (a flag) and a config that puts each of the task's synthesis settings back to
    SynthConfig's own default win over the task's block, on every built-in task."""
    assert resolve("shadow", task, flags={"synth": {"seeds_per_grasp": 1}}).synth.seeds_per_grasp == 1
    block = {k: v for k, v in load_task(task).synth.items() if k in SynthConfig.__dataclass_fields__
             and not isinstance(v, dict)}
    default = SynthConfig()
    back = resolve("shadow", task, config={"synth": {k: getattr(default, k) for k in block}}).synth
    assert all(getattr(back, k) == getattr(default, k) for k in block), block


def test_nested_mappings_merge_key_by_key_and_presets_differ_only_where_they_say():
    r = resolve("shadow", "lift_plate", config={"synth": {"weights": {"task": 0.0}, "contact": {"mu": 0.4}}})
    assert r.synth.weights.task == 0.0 and r.synth.weights.distance == 1e5  # the task's distance weight kept
    assert r.synth.contact.mu == 0.4 and r.synth.contact.normalize is True
    paper, dataset = resolve("shadow", preset="paper"), resolve("shadow")
    assert (paper.synth.iters, paper.synth.seeds_per_grasp, paper.grid_resolution) == (500, 1, 64)
    assert (dataset.synth.iters, dataset.synth.seeds_per_grasp, dataset.grid_resolution) == (300, 16, 48)
    assert paper.process.coacd_threshold == 0.05 and dataset.process.coacd_threshold == 0.1
    assert paper.synth == SynthConfig(task="force_closure")  # the library defaults
    # the preset named in a config, overridden by the flags'
    assert resolve("shadow", config={"preset": "paper"}).preset == "paper"
    assert resolve("shadow", config={"preset": "paper"}, flags={"preset": "dataset"}).synth.iters == 300
    assert set(PRESETS) == {"dataset", "paper"}


def test_the_squeeze_is_computed_for_the_evaluations_actuator_gain():
    from datagen.eval.protocol import PEER_GAINS

    r = resolve("shadow", config={"eval": {"actuator_kp": 3.0}})
    assert r.eval.actuator_kp == 3.0 and r.synth.squeeze_kp == 3.0
    # the peer's gains for a hand it shares, under its protocol (the default); uniform: actuator_kp
    assert resolve("leap").synth.squeeze_kp == PEER_GAINS["leap"].kp == 3.0
    assert resolve("leap", config={"eval": {"protocol": "uniform"}}).synth.squeeze_kp == 5.0
    with pytest.raises(ConfigError, match="actuator_kp"):
        resolve("shadow", config={"synth": {"squeeze_kp": 3.0}})


def test_bad_settings_are_named():
    with pytest.raises(ConfigError, match="preset 'fast'"):
        resolve("shadow", preset="fast")
    with pytest.raises(ConfigError, match=r"job.yaml: synth.*unknown keys \['iterations'\]"):
        resolve("shadow", config={"synth": {"iterations": 3}}, where="job.yaml")
    with pytest.raises(ConfigError, match="synth must be a mapping"):
        resolve("shadow", config={"synth": 300})


def test_a_loose_synth_field_at_the_top_of_a_config_file_is_refused(tmp_path):
    from datagen.pipeline.commands import read_config

    (tmp_path / "old.yaml").write_text("iters: 200\n")
    with pytest.raises(ConfigError, match=r"old.yaml: SynthConfig fields \['iters'\] at the top level"):
        read_config(str(tmp_path / "old.yaml"))
    (tmp_path / "proc.yaml").write_text("coacd_threshold: 0.05\n")
    with pytest.raises(ConfigError, match=r"ProcessConfig fields \['coacd_threshold'\].*under `process:`"):
        read_config(str(tmp_path / "proc.yaml"))
    (tmp_path / "new.yaml").write_text("synth: {iters: 200}\n")
    assert read_config(str(tmp_path / "new.yaml")) == {"synth": {"iters": 200}}


def test_synthesis_refuses_a_config_that_lacks_its_tasks_block():
    key = load_task("precision_key")
    with pytest.raises(ConfigError, match="precision_key.*exact_contacts.*resolve"):
        SynthConfig().check_task(key)
    resolve("shadow", "precision_key").synth.check_task(key)  # resolved: fine
    SynthConfig().check_task(load_task("force_closure"))  # no block to lose


IDENTITY = {"object_id", "object_path", "split", "grasp_id"}  # what the caller names, not what is synthesized


def _same(rows):
    def c(v):
        if isinstance(v, float) and math.isnan(v):
            return "nan"
        return [c(x) for x in v] if isinstance(v, list) else v
    return [{k: c(v) for k, v in r.items() if k not in IDENTITY} for r in rows]


@pytest.mark.slow
@pytest.mark.mujoco
@pytest.mark.ray
def test_library_call_synth_command_and_a_one_object_job_make_the_same_grasps(tmp_path):
    """The defaults everywhere (the dataset preset: 16 starts, 300 iterations, the job's CoACD
    and grid), one mesh, one scale, seed 0: the rows agree on every synthesized and evaluated
    column (only the object's id, path and split are the caller's)."""
    import datagen
    from datagen.cli import main

    root, cache = tmp_path / "meshes", str(tmp_path / "cache")
    root.mkdir()
    trimesh.creation.box((1.0, 0.7, 0.5)).export(root / "box.obj")
    lib = datagen.synthesize("shadow", root / "box.obj", n=2, scales=(0.08,), cache=cache).to_pylist()
    assert main(["synth", "--object", str(root / "box.obj"), "--num", "2", "--cache", cache,
                 "--out", str(tmp_path / "g.parquet")]) == 0
    assert main(["eval", str(tmp_path / "g.parquet"), "--cache", cache, "--out", str(tmp_path / "e.parquet")]) == 0
    cli = pq.read_table(tmp_path / "e.parquet").to_pylist()
    (tmp_path / "job.yaml").write_text(yaml.safe_dump({"scales": [0.08]}))
    assert main(["run", "--out", str(tmp_path / "job"), "--source", f"dir:{root}", "--objects", "1", "--grasps", "2",
                 "--config", str(tmp_path / "job.yaml"), "--cache", cache, "--num-cpus", "1", "--no-progress"]) == 0
    job = pq.read_table(next((tmp_path / "job" / "shards").glob("*.parquet"))).to_pylist()
    assert len(lib) == 2 and lib[0]["seed"] == 0
    assert _same(lib) == _same(cli) == _same(job)


def test_grasp_types_resolve_like_a_layer_and_a_name_means_every_grasp():
    from datagen.tasks import GraspMix

    bands = {"bands": [{"max_scale_m": 0.09, "mix": {"precision": 1}}, {"mix": {"power": 1}}]}
    r = resolve("shadow", "force_closure", config={"grasp_types": bands})
    assert r.grasp_types.counts(0.06, 2) == {"precision": 2} and r.grasp_types.counts(0.12, 2) == {"power": 2}
    flagged = resolve("shadow", "force_closure", config={"grasp_types": bands}, flags={"grasp_types": "precision"})
    assert flagged.grasp_types == GraspMix.single("precision")
    dataset = resolve("shadow", "force_closure").grasp_types
    assert dataset.counts(0.06, 2, 0.03) == {"edge_pinch": 2} and dataset.counts(0.06, 2) == {"precision": 2}
    # on a table, not lying flat: the small band's tabletop mix; the power band has none
    assert dataset.counts(0.06, 2, 0.05) == {"edge_pinch": 2} and dataset.counts(0.12, 2, 0.08) == {"power": 2}
    assert r.grasp_types.counts(0.06, 2, 0.05) == {"precision": 2}  # the user's bands have no tabletop mix
    assert r.grasp_types.counts(0.06, 2, 0.03) == {"edge_pinch": 2}  # the user's bands keep the preset's flat band
    assert flagged.grasp_types.counts(0.06, 2, 0.03) == {"precision": 2}  # a name: every grasp of that type
    assert resolve("shadow", "force_closure").grasp_types == GraspMix.from_dict(PRESETS["dataset"].get("grasp_types"))
    assert r.hash() != resolve("shadow", "force_closure", flags={"grasp_types": "precision"}).hash()
    with pytest.raises(ConfigError, match="unknown grasp type 'grip'"):
        resolve("shadow", "force_closure", flags={"grasp_types": "grip"})
    with pytest.raises(ConfigError, match="synth.grasp_type is chosen per object size by grasp_types"):
        resolve("shadow", "force_closure", config={"synth": {"grasp_type": "power"}})
    with pytest.raises(ConfigError, match="grasp_types must be a grasp type's name or a mapping"):
        resolve("shadow", "force_closure", config={"grasp_types": 3})
