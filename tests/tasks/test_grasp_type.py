"""Grasp types as data: the built-in YAMLs, their validation, and the per-size mix."""

import pytest

from datagen.errors import ConfigError
from datagen.tasks import GraspMix, GraspType, builtin_grasp_types, load_grasp_type


def test_builtin_grasp_types_load_and_name_their_contacts():
    assert {"precision", "power", "edge_pinch"} <= set(builtin_grasp_types())
    assert not load_grasp_type("edge_pinch").extra_contacts and load_grasp_type("edge_pinch").init["kind"] == "rim"
    assert not load_grasp_type("precision").extra_contacts
    power = load_grasp_type("power")
    assert power.role("palm") == "pull" and power.role("phalanges") in ("pull", "candidate")


@pytest.mark.parametrize("data, match", [
    ({"name": "x", "contacts": {"wrist": "pull"}}, "unknown contact role 'wrist'"),
    ({"name": "x", "contacts": {"palm": "press"}}, "contacts.palm must be one of"),
    ({"name": "x", "init": {"distance": [0, 1]}}, "unknown init field"),
    ({"name": "task"}, "reserved"),
    ({"name": "a b"}, "simple identifier"),
    ({"name": "x", "synth": {"seed": 3}}, "set by the job"),
    ({"name": "x", "extra": {}}, "extra"),
    ({"name": "x", "hands": {"leap": {"init": {"distance": [0, 1]}}}}, r"hands\.leap: unknown init field\(s\) \['distance'\]"),
    ({"name": "x", "hands": {"leap": {"synth": {"task": "t"}}}}, r"hands\.leap: synth\.task is set by the job"),
    ({"name": "x", "hands": {"leap": {"init": {"distance_m": [0.04, 0.01]}}}}, r"hands\.leap\.init.*increasing pair"),
    ({"name": "x", "init": {"curl": 0.3}, "hands": {"leap": {"init": {"curl": 1.5}}}}, r"hands\.leap\.init.*curl"),
    ({"name": "x", "hands": {"leap": {"fingers": ["th"]}}}, r"hands\.leap.*fingers"),
    ({"name": "x", "hands": ["leap"]}, "hands"),
])
def test_bad_grasp_type_is_named(data, match):
    with pytest.raises(ConfigError, match=match):
        GraspType.from_dict(data)


def test_grasp_type_yaml_file_and_unknown_name(tmp_path):
    p = tmp_path / "wrap.yaml"
    p.write_text("name: wrap\ncontacts: {palm: pull, phalanges: pull}\ninit: {distance_m: [0.01, 0.02]}\n")
    t = load_grasp_type(p)
    assert t.name == "wrap" and t.role("phalanges") == "pull"
    from datagen.tasks import load_task

    init = t.apply_init(load_task("force_closure").init)
    assert init.distance_m == (0.01, 0.02) and init.kind == "surround"
    with pytest.raises(ConfigError, match="unknown grasp type 'pwr'"):
        load_grasp_type("pwr")


def test_a_hands_entry_goes_over_the_type_for_that_hand_only(tmp_path):
    """``hands.leap``: its init fields replace the type's, its synth mappings merge key by key into
    the type's block, for LEAP's recipe only; Shadow's recipe gets the type's own layer."""
    from datagen.pipeline import resolve

    p = tmp_path / "grip.yaml"
    p.write_text("name: grip\ncontacts: {palm: pull}\ninit: {kind: wrap, curl: 0.3, distance_m: [0.03, 0.06]}\n"
                 "synth: {weights: {penetration: 50.0}, iters: 200}\n"
                 "hands:\n  leap: {init: {distance_m: [0.015, 0.04]}, synth: {weights: {distance: 7.0}}}\n")
    t = load_grasp_type(p)
    leap, shadow = t.for_hand("leap"), t.for_hand("shadow")
    assert dict(leap.init) == {"kind": "wrap", "curl": 0.3, "distance_m": [0.015, 0.04]} and not leap.hands
    assert dict(leap.synth) == {"weights": {"penetration": 50.0, "distance": 7.0}, "iters": 200}
    assert (dict(shadow.init), dict(shadow.synth)) == (dict(t.init), dict(t.synth)) and not shadow.hands
    from datagen.tasks import load_task

    assert leap.apply_init(load_task("force_closure").init).distance_m == (0.015, 0.04)
    lc, sc = (resolve(h, config={"grasp_types": str(p)}).synth_for(str(p)) for h in ("leap", "shadow"))
    assert (lc.weights.penetration, lc.weights.distance, lc.iters) == (50.0, 7.0, 200)
    assert (sc.weights.penetration, sc.iters) == (50.0, 200) and sc.weights.distance != 7.0


def test_an_edited_task_or_type_yaml_is_another_recipe(tmp_path):
    """What a task or grasp type YAML defines for a hand is part of its recipe
    (`Recipe.definitions`): editing the type's start, its contacts or the task's fingers changes
    the recipe's hash (job.json records the recipes; a shard whose resolution differs from them
    stops: `workers.shard.same_recipes`); another hand's entry leaves this hand's recipe alone."""
    from datagen.pipeline import resolve

    t, task = tmp_path / "grip.yaml", tmp_path / "pinch.yaml"
    t.write_text("name: grip\ncontacts: {palm: pull}\ninit: {kind: wrap, distance_m: [0.03, 0.06]}\n")
    task.write_text("name: pinch\nfingers: [th, ff]\n")
    cfg = {"grasp_types": str(t)}

    def h(hand="shadow"):
        return resolve(hand, task=str(task), config=cfg).hash()

    before, leap = h(), h("leap")
    t.write_text("name: grip\ncontacts: {palm: pull}\ninit: {kind: wrap, distance_m: [0.03, 0.06]}\n"
                 "hands:\n  leap: {init: {distance_m: [0.015, 0.04]}}\n")
    assert h() == before and h("leap") != leap  # LEAP's entry: LEAP's recipe only
    for text in ("name: grip\ncontacts: {palm: pull}\ninit: {kind: wrap, distance_m: [0.01, 0.02]}\n",
                 "name: grip\ncontacts: {palm: candidate}\ninit: {kind: wrap, distance_m: [0.03, 0.06]}\n"):
        t.write_text(text)
        assert h() != before
    t.write_text("name: grip\ncontacts: {palm: pull}\ninit: {kind: wrap, distance_m: [0.03, 0.06]}\n")
    assert h() == before
    task.write_text("name: pinch\nfingers: [th, ff, mf]\n")
    assert h() != before


def test_grasp_type_synth_is_a_layer_between_the_task_and_the_users_config(tmp_path):
    """A type's ``synth:`` block goes over the preset and the task (mappings key by key) for its
    grasps only; the user's config and flags win over it, even with a default's value; the
    precision type (no block) synthesizes with the recipe's own settings."""
    from datagen.pipeline import resolve

    p = tmp_path / "hold.yaml"
    p.write_text("name: hold\nsynth: {weights: {penetration: 1000000.0}, sphere_margin_m: 0.0, iters: 50}\n")
    mix = {"bands": [{"max_scale_m": 0.09, "mix": {"precision": 1.0}}, {"mix": {str(p): 1.0}}]}
    r = resolve("shadow", config={"grasp_types": mix, "synth": {"weights": {"distance": 5e3}}})
    cfg = r.synth_for(str(p))
    assert (cfg.weights.penetration, cfg.weights.distance) == (1e6, 5e3)  # merged key by key
    assert (cfg.sphere_margin_m, cfg.iters, cfg.seeds_per_grasp, cfg.grasp_type) == (0.0, 50, 16, str(p))
    assert r.synth_for("precision") == r.synth  # no block: the recipe's settings
    user = resolve("shadow", config={"grasp_types": mix, "synth": {"iters": 300}},  # the preset's value, set
                   flags={"synth": {"weights": {"penetration": 2.0}}}).synth_for(str(p))
    assert (user.iters, user.weights.penetration, user.sphere_margin_m) == (300, 2.0, 0.0)
    for k, (bad, match) in enumerate((("{iterz: 10}", "iterz"), ("{weights: {penetration: -1}}", "penetration"))):
        q = tmp_path / f"bad{k}.yaml"
        q.write_text(f"name: bad{k}\nsynth: {bad}\n")
        with pytest.raises(ConfigError, match=match):
            resolve("shadow", config={"grasp_types": str(q)})


def test_a_types_synth_block_reaches_its_grasps_and_the_users_config_wins(monkeypatch):
    """Through the job's path (`synthesize_rows` with the recipe's layers): the power grasps of a
    0.10 m object get the type's pieces and margin scale, unless the user's config sets one."""
    from types import SimpleNamespace

    from datagen.pipeline import batch, resolve
    from datagen.tasks import load_task

    class Stop(Exception):
        pass

    seen = []

    def fake(hand, group, task, c, n, **kw):
        seen.append(c)
        raise Stop

    monkeypatch.setattr("datagen.synth.synthesize", fake)
    target = SimpleNamespace(scale=0.10, support_plane=None)
    for config, want in (({}, (True, 0.75)), ({"synth": {"penetration_pieces": False}}, (False, 0.75)),
                         ({"synth": {"sphere_margin_scale": 1.0}}, (True, 1.0))):
        r = resolve("shadow", config=config)  # the dataset preset: power grasps above 0.09 m
        with pytest.raises(Stop):
            batch.synthesize_rows(None, [target], load_task("force_closure"), r.synth, 1,
                                  grasp_types=r.grasp_types, type_synth=r.grasp_type_synth)
        assert (seen[-1].grasp_type, seen[-1].penetration_pieces, seen[-1].sphere_margin_scale) == ("power", *want)


def test_mix_counts_by_size_and_share():
    mix = GraspMix.from_dict({"bands": [{"max_scale_m": 0.09, "mix": {"precision": 1}},
                                        {"mix": {"power": 0.5, "precision": 0.5}}]})
    assert mix.counts(0.06, 4) == {"precision": 4}
    assert mix.counts(0.09, 4) == {"precision": 4}  # the band's bound is inclusive
    assert mix.counts(0.12, 4) == {"power": 2, "precision": 2}
    assert mix.counts(0.12, 3) == {"power": 2, "precision": 1}  # largest remainder, ties in the mix's order
    assert mix.counts(0.12, 1) == {"power": 1}
    assert mix.types() == ["precision", "power"]
    assert GraspMix.single("power").counts(0.06, 5) == {"power": 5}
    assert GraspMix.from_dict(mix.to_dict()) == mix


def test_flat_band_takes_objects_lying_flat_on_a_table_at_any_scale():
    mix = GraspMix.from_dict({"bands": [{"max_scale_m": 0.09, "mix": {"precision": 1}}, {"mix": {"power": 1}}],
                              "flat": {"max_height_m": 0.04, "mix": {"edge_pinch": 1}}})
    assert mix.counts(0.06, 2, 0.03) == {"edge_pinch": 2} and mix.counts(0.12, 2, 0.03) == {"edge_pinch": 2}
    assert mix.counts(0.06, 2, 0.04) == {"edge_pinch": 2}  # the bound is inclusive
    assert mix.counts(0.06, 2, 0.041) == {"precision": 2} and mix.counts(0.12, 2, 0.05) == {"power": 2}
    assert mix.counts(0.06, 2) == {"precision": 2}  # floating: the bands
    assert mix.types() == ["precision", "power", "edge_pinch"]
    assert GraspMix.from_dict(mix.to_dict()) == mix
    assert GraspMix().counts(0.06, 2, 0.01) == {"precision": 2}  # no flat band: the bands for every object


def test_a_bands_tabletop_mix_takes_its_objects_resting_on_a_table():
    mix = GraspMix.from_dict({"bands": [{"max_scale_m": 0.09, "mix": {"precision": 1}, "tabletop": {"edge_pinch": 1}},
                                        {"mix": {"power": 1}}],
                              "flat": {"max_height_m": 0.04, "mix": {"precision": 1}}})
    assert mix.counts(0.06, 2) == {"precision": 2}  # floating: the band's mix
    assert mix.counts(0.06, 2, 0.05) == {"edge_pinch": 2}  # on a table: its tabletop mix
    assert mix.counts(0.06, 2, 0.03) == {"precision": 2}  # lying flat: the flat band's, before the tabletop mix
    assert mix.counts(0.12, 2, 0.08) == {"power": 2}  # a band without one: its mix on a table too
    assert mix.types() == ["precision", "power", "edge_pinch"]
    assert GraspMix.from_dict(mix.to_dict()) == mix
    with pytest.raises(ConfigError, match="tabletop must map grasp types to shares"):
        GraspMix.from_dict({"bands": [{"mix": {"precision": 1}, "tabletop": {"edge_pinch": 0.5}}]})
    with pytest.raises(ConfigError, match="unknown grasp type 'claw'"):
        GraspMix.from_dict({"bands": [{"mix": {"precision": 1}, "tabletop": {"claw": 1}}]})


@pytest.mark.parametrize("flat, match", [
    ({"max_height_m": 0, "mix": {"edge_pinch": 1}}, "max_height_m must be a positive"),
    ({"mix": {"edge_pinch": 0.5}}, "summing to 1"),
    ({"mix": {"claw": 1}}, "unknown grasp type 'claw'"),
])
def test_bad_flat_band_is_named(flat, match):
    with pytest.raises(ConfigError, match=match):
        GraspMix.from_dict({"bands": [{"mix": {"precision": 1}}], "flat": flat})


@pytest.mark.parametrize("bands, match", [
    ([{"max_scale_m": 0.1, "mix": {"precision": 1}}], "must end with a band without max_scale_m"),
    ([{"max_scale_m": 0.1}, {"max_scale_m": 0.08}, {}], "must increase"),
    ([{"mix": {"precision": 0.5}}], "summing to 1"),
    ([{"mix": {"hook": 1}}], "unknown grasp type 'hook'"),
])
def test_bad_mix_is_named(bands, match):
    with pytest.raises(ConfigError, match=match):
        GraspMix.from_dict({"bands": bands})


def test_a_types_margin_scale_takes_part_of_each_hands_margin():
    """``sphere_margin_scale`` (a type's ``synth:``) multiplies the hand spec's margin (Shadow 1.5 mm,
    Allegro 0.5 mm); an explicit ``sphere_margin_m`` wins; out of [0, 1] is refused."""
    from types import SimpleNamespace

    from datagen.synth.config import SynthConfig

    shadow, allegro = SimpleNamespace(sphere_margin_m=0.0015), SimpleNamespace(sphere_margin_m=0.0005)
    half = SynthConfig(sphere_margin_scale=0.5)
    assert half.for_hand(shadow).sphere_margin_m == pytest.approx(0.00075, abs=1e-12)
    assert half.for_hand(allegro).sphere_margin_m == pytest.approx(0.00025, abs=1e-12)
    assert SynthConfig(sphere_margin_scale=0.5, sphere_margin_m=0.001).for_hand(shadow).sphere_margin_m == 0.001
    with pytest.raises(ConfigError, match="sphere_margin_scale"):
        SynthConfig(sphere_margin_scale=1.5)
