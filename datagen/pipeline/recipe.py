"""One resolved configuration per hand and task (a `Recipe`), built by one resolver.

Every entry point -- the library call (`datagen.synthesize`), ``datagen synth``, ``datagen
run`` and its shards, the benchmarks -- gets its settings from `resolve`, which stacks these
layers, each a partial mapping of the recipe's parts (``synth``, ``eval``, ``process``,
``grasp_types``, ``grid_resolution``, ``scene``), in this order::

    library defaults   the config dataclasses' own (SynthConfig, EvalConfig, ProcessConfig)
    preset             PRESETS[name]: "dataset" (the default: what a job runs) or "paper"
    task               the task YAML's ``synth:`` block
    grasp type         the ``synth:`` block of each grasp type of ``grasp_types`` (its grasps only)
    config             the user's config file or mapping
    flags              explicit command-line flags (or keyword arguments)

A key a layer lacks is unset, and the layer below decides; a key a layer sets wins, even when
it equals a default (``--seeds 1`` is one seed on every task). Nested mappings (``weights``,
``contact``) merge key by key. ``grasp_types`` (a `datagen.tasks.GraspMix`: which grasp type
each force-closure grasp gets, by object size) may also be a grasp type's name (every grasp of
that type: ``--grasp-type power``); the synthesis settings of a type's grasps are
`Recipe.synth_for` (the grasp-type layer above: ``grasp_type_synth``, the fields in which they
differ from ``synth``). ``scene`` (a `datagen.objects.tabletop.SceneConfig`: floating,
or resting on a table in its stable poses) may also be the scene's name (``scene: tabletop``). The squeeze is computed for the evaluation's actuator stiffness of
the hand (`squeeze_kp`: its protocol's gains), never set on its own. The result is a frozen `Recipe`: what a job records in job.json
and hashes, and what ``datagen synth`` writes into its table's metadata.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from datagen.config import Config, merge_layers, stable_hash
from datagen.errors import ConfigError
from datagen.eval.config import EvalConfig
from datagen.objects.config import ProcessConfig
from datagen.objects.tabletop import SCENES, SceneConfig
from datagen.synth.config import SynthConfig
from datagen.tasks.grasp_type import GraspMix

__all__ = ["DEFAULT_PRESET", "PRESETS", "RECIPE_KEYS", "Recipe", "for_grasp_type", "merge_layers", "resolve"]

#: the parts of a configuration layer (a config file may hold other keys: a job's source, count, ...)
RECIPE_KEYS = ("synth", "eval", "process", "grasp_types", "grid_resolution", "scene")

# A cheap CoACD setting: threshold 0.1 and preprocess resolution 30 are 2-3x faster than the
# objects package's defaults (0.05 / 50) and give coarser but adequate pieces for the hold test
# (NOTES §5, benchmarks/results/objects.md).
_FAST_PROCESS = {"coacd_threshold": 0.1, "coacd_preprocess_resolution": 30, "coacd_mcts_iterations": 60,
                 "coacd_mcts_nodes": 10}

PRESETS: dict[str, dict[str, Any]] = {
    # What a dataset job runs: the best of 16 starts per grasp (by the whole hand's epsilon after
    # 120 iterations) raised six-direction success on the real-object set from 38% to 73% (Shadow,
    # 8 starts) and the 0.08 m probe from 68% to 82% (16; benchmarks/results/quality.md); 300
    # iterations; a 48^3 SDF grid (~10 s per object on one core) and the fast CoACD setting.
    # Objects above 0.09 m get power grasps (palm and phalanges in the contact set): Shadow on
    # the real development objects 44% -> 69% at 0.10 m and 25% -> 44% at 0.12 m, held out
    # 20% -> 50% at 0.12 m, the other hands unchanged (issue 41, benchmarks/results/quality.md).
    # The fingertip grasps at 0.06-0.08 m are unchanged. The power type starts pre-curled and
    # keeps out of the convex pieces (issue 41's third round): Shadow 58% / 36% -> 78% / 36%,
    # held out 55% / 45% -> 70% / 55%, E3M5 42% / 33% -> 67% / 50%, successes' penetration p90
    # <= 0.6 mm (benchmarks/results/sizes.md);
    # its starts face the object across its longest axis (fourth round, `init.kind: wrap`): E3M5
    # 54% / 46% -> 83% / 71%, Shadow 78% / 39% -> 69% / 53%, LEAP 92% / 75% -> 83% / 67%. With
    # those starts power grasps hold bigger objects too: at 0.15 m 66 of 112 rows over the four
    # hands against the fingertip grasps' 43 (Shadow 7% -> 43%, E3M5 21% -> 54%, Allegro 61% ->
    # 86%, LEAP 64% -> 54%; benchmarks/results/quality.md), so every object above 0.09 m gets them.
    # An object lying flat on a table (its top at most 4 cm above it) gets edge pinches (issue 45):
    # Shadow on the flat development objects 40% -> 70% lifted (benchmarks/results/tabletop.md).
    # So does every other object up to 0.09 m on a table (the claw from above, its tabletop mix):
    # development 100 -> 105 of 128 lifted over the four hands (E3M5 +2, Allegro +3, LEAP +1,
    # Shadow -1), held out 72 -> 81 of 96 (benchmarks/results/tabletop.md).
    "dataset": {"synth": {"iters": 300, "seeds_per_grasp": 16}, "process": dict(_FAST_PROCESS),
                "grid_resolution": 48,
                "grasp_types": {"bands": [{"max_scale_m": 0.09, "mix": {"precision": 1.0}, "tabletop": {"edge_pinch": 1.0}},
                                          {"mix": {"power": 1.0}}],
                                "flat": {"max_height_m": 0.04, "mix": {"edge_pinch": 1.0}}}},
    # The paper's synthesis: one start per pose, 500 iterations (the library defaults), a 64^3
    # grid, the objects package's CoACD defaults (threshold 0.05) and fingertip grasps only.
    "paper": {"grid_resolution": 64},
}
DEFAULT_PRESET = "dataset"


@dataclass(frozen=True)
class Recipe(Config):
    """Everything that decides the grasps of one hand and task on an object, resolved."""

    hand: str = "shadow"  #: built-in hand name or hand spec YAML path
    task: str = "force_closure"  #: built-in task name or task YAML path
    preset: str = DEFAULT_PRESET  #: the preset it was resolved from (a key of PRESETS)
    synth: SynthConfig = field(default_factory=SynthConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    process: ProcessConfig = field(default_factory=ProcessConfig)
    grid_resolution: int = 64  #: synthesis SDF grid nodes per axis (built once per object)
    #: which grasp type (`datagen.tasks.grasp_type`) each grasp of a force-closure task on every
    #: fingertip gets, by object size; other tasks are their own contact set (precision)
    grasp_types: GraspMix = field(default_factory=GraspMix)
    #: where the object is: floating (gravity off, the six-direction test) or resting on a table
    #: in its stable poses (the lift test; docs/scenes.md)
    scene: SceneConfig = field(default_factory=SceneConfig)
    #: grasp type (as ``grasp_types`` names it) -> the `SynthConfig` fields in which its grasps'
    #: settings differ from ``synth``: its YAML's ``synth:`` block less what the config and the
    #: flags set (`resolve`); a type not listed synthesizes with ``synth``
    grasp_type_synth: dict[str, Any] = field(default_factory=dict)
    #: the sha256 (16 hex digits) of what the task and each grasp type of ``grasp_types`` define
    #: for this hand (the YAML as loaded, its ``hands`` entry applied: fingers, starts, contacts,
    #: ``synth:`` blocks), keyed ``task`` and ``grasp_type <name>``: an edited task or type YAML is
    #: another recipe, so a resumed job refuses it (`workers.shard.same_recipes`)
    definitions: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        if self.preset not in PRESETS:
            raise ConfigError(f"Recipe.preset: unknown preset {self.preset!r}", f"choose from {sorted(PRESETS)}")
        if not 8 <= self.grid_resolution <= 256:
            raise ConfigError(f"Recipe.grid_resolution must be in 8..256 (nodes per axis), got {self.grid_resolution}")

    def load_task(self):
        """The task's `datagen.tasks.TaskSpec`."""
        from datagen.tasks import load_task

        return load_task(self.task)

    def synth_for(self, grasp_type: str) -> SynthConfig:
        """The `SynthConfig` of ``grasp_type``'s grasps (``grasp_type`` set, its layer applied)."""
        return for_grasp_type(self.synth, grasp_type, self.grasp_type_synth)


def for_grasp_type(cfg: SynthConfig, grasp_type: str, overrides: Mapping[str, Any] | None = None) -> SynthConfig:
    """``cfg`` for the grasps of ``grasp_type``: that type named, with ``overrides[grasp_type]``
    (a `Recipe.grasp_type_synth`: fields by type; None or a type not in it: none) over it."""
    over = dict((overrides or {}).get(grasp_type) or {})
    if not over:
        return cfg if cfg.grasp_type == grasp_type else dataclasses.replace(cfg, grasp_type=grasp_type)
    data = merge_layers(cfg.to_dict(), over, {"grasp_type": grasp_type})
    return SynthConfig.from_dict(data, where=f"grasp type {grasp_type!r}: synth")


def _differences(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, Any]:
    """The keys of ``b`` whose values differ from ``a``'s (nested mappings: their differing keys)."""
    out: dict[str, Any] = {}
    for k, v in b.items():
        if isinstance(v, Mapping) and isinstance(a.get(k), Mapping):
            sub = _differences(a[k], v)
            if sub:
                out[k] = sub
        elif a.get(k) != v:
            out[k] = v
    return out


def _grasp_type_layers(mix: GraspMix, below: list, above: list, synth: SynthConfig, extra: Mapping[str, Any],
                       where: str, hand_name: str) -> dict[str, Any]:
    """`Recipe.grasp_type_synth`: for each type of ``mix`` with a ``synth:`` block (its ``hands``
    entry for ``hand_name`` merged over it), its layer between the layers ``below`` (defaults to
    task) and ``above`` (config, flags), as the fields that differ from ``synth`` (the recipe's
    without it); ``extra``: the fields set by the recipe."""
    from datagen.tasks.grasp_type import load_grasp_type

    out: dict[str, Any] = {}
    for name in mix.types():
        block = dict(load_grasp_type(name).for_hand(hand_name).synth)
        if not block:
            continue
        layered = merge_layers(*below, {"synth": block}, *above).get("synth", {})
        cfg = SynthConfig.from_dict({**layered, **extra, "grasp_type": name}, where=f"{where}: grasp type {name!r}: synth")
        diff = _differences(synth.to_dict(), {k: v for k, v in cfg.to_dict().items() if k != "grasp_type"})
        if diff:
            out[name] = diff
    return out


def _definitions(spec, mix: GraspMix, hand_name: str) -> dict[str, str]:
    """`Recipe.definitions`: the digests of the task ``spec`` and of each type of ``mix`` as hand
    ``hand_name`` gets them."""
    from datagen.tasks.grasp_type import load_grasp_type

    out = {"task": stable_hash(spec.for_hand(hand_name).to_dict())[:16]}
    for name in mix.types():
        out[f"grasp_type {name}"] = stable_hash(load_grasp_type(name).for_hand(hand_name).to_dict())[:16]
    return out


def _layer(data: Mapping[str, Any] | None, where: str) -> dict[str, Any]:
    """A configuration layer: only the recipe's keys (and ``preset``), each part a mapping."""
    data = dict(data or {})
    for k in ("synth", "eval", "process"):
        if k in data and data[k] is not None and not isinstance(data[k], Mapping):
            raise ConfigError(f"{where}: {k} must be a mapping of fields, got {type(data[k]).__name__}")
    if "grasp_type" in (data.get("synth") or {}):
        raise ConfigError(f"{where}: synth.grasp_type is chosen per object size by grasp_types",
                          "set grasp_types (a grasp type's name, or bands of shares) instead")
    if isinstance(data.get("grasp_types"), str):  # one type's name or YAML path: every grasp of it
        data["grasp_types"] = GraspMix.single(data["grasp_types"]).to_dict()
    elif data.get("grasp_types") is not None and not isinstance(data["grasp_types"], Mapping):
        raise ConfigError(f"{where}: grasp_types must be a grasp type's name or a mapping with bands, "
                          f"got {type(data['grasp_types']).__name__}")
    if isinstance(data.get("scene"), str):  # the scene's name: its kind, one stable pose
        data["scene"] = {"kind": data["scene"]}
    elif data.get("scene") is not None and not isinstance(data["scene"], Mapping):
        raise ConfigError(f"{where}: scene must be a scene's name ({' or '.join(SCENES)}) or a mapping "
                          f"(kind, stable_poses), got {type(data['scene']).__name__}")
    if "squeeze_kp" in (data.get("synth") or {}):
        raise ConfigError(f"{where}: synth.squeeze_kp is the evaluation's actuator_kp",
                          "set eval.actuator_kp instead (the squeeze is computed for it)")
    return {k: data[k] for k in (*RECIPE_KEYS, "preset") if data.get(k) is not None}


def squeeze_kp(hand: str | Path, ev: EvalConfig) -> float:
    """The stiffness (N m/rad) of the hand's finger actuators in the evaluation: the squeeze is
    computed for it (`datagen.eval.protocol.hand_gains`; a spec path's hand by its spec's name)."""
    from datagen.eval.protocol import hand_gains

    return float(hand_gains(ev, hand_name(hand), 0.0).kp)


def hand_name(hand: str | Path) -> str:
    """A built-in hand's name, or the name in the spec of a spec path."""
    from datagen.hands import BUILTIN_HANDS, load_spec

    return str(hand) if str(hand) in BUILTIN_HANDS else load_spec(hand).name


def resolve(hand: str = "shadow", task: str | Path = "force_closure", *, preset: str | None = None,
            config: Mapping[str, Any] | None = None, flags: Mapping[str, Any] | None = None,
            where: str = "config") -> Recipe:
    """The `Recipe` of ``hand`` and ``task`` (names or YAML paths): library defaults, then the
    preset (``preset`` argument, else the flags', else the config's, else `DEFAULT_PRESET`), the
    task's ``synth:`` block, ``config`` (the user's settings: a mapping with any of `RECIPE_KEYS`;
    other keys are ignored) and ``flags`` (the same shape). ``where`` names ``config`` in errors.
    Raises `ConfigError` naming the field for an unknown preset, key or value."""
    from datagen.tasks import load_task

    user, explicit = _layer(config, where), _layer(flags, "flags")
    name = preset or explicit.pop("preset", None) or user.pop("preset", None) or DEFAULT_PRESET
    user.pop("preset", None)
    if name not in PRESETS:
        raise ConfigError(f"preset {name!r} is not known", f"choose from {sorted(PRESETS)}")
    spec = load_task(task)
    below, above = [PRESETS[name], {"synth": dict(spec.synth)}], [user, explicit]
    merged = merge_layers(*below, *above)
    ev = EvalConfig.from_dict(merged.get("eval"), where=f"{where}: eval")
    extra = {"task": spec.name, "squeeze_kp": squeeze_kp(hand, ev)}
    synth = SynthConfig.from_dict({**merged.get("synth", {}), **extra}, where=f"{where}: synth (task {spec.name!r})")
    process = ProcessConfig.from_dict(merged.get("process"), where=f"{where}: process")
    mix = GraspMix.from_dict(merged.get("grasp_types"), where=f"{where}: grasp_types")
    scene = SceneConfig.from_dict(merged.get("scene"), where=f"{where}: scene")
    if scene.tabletop and spec.eval != "six_direction":
        raise ConfigError(f"{where}: scene tabletop: task {spec.name!r} has its own test (eval block), which has no table",
                          "use scene tabletop with force-closure tasks (the six-direction test becomes the lift)")
    who = hand_name(hand)
    return Recipe(hand=str(hand), task=str(task), preset=name, synth=synth, eval=ev, process=process,
                  grid_resolution=int(merged.get("grid_resolution", Recipe.grid_resolution)), grasp_types=mix,
                  scene=scene, grasp_type_synth=_grasp_type_layers(mix, below, above, synth, extra, where, who),
                  definitions=_definitions(spec, mix, who))
