"""The committed real-object manifests (benchmarks/make_real_manifest.py): valid, disjoint, and
pinned to the bytes of the installed registry packages (skipped where `make real-objects` has not
installed them)."""

import hashlib
import importlib.util
import json
from pathlib import Path

import pytest

from datagen.objects.manifest import load_manifest

MANIFESTS = Path(__file__).resolve().parents[2] / "manifests"
SETS = ("real_dev.jsonl", "real_holdout.jsonl")


def _require_packages(*names: str) -> None:
    """Skip unless the registry packages every entry of these manifests loads from are installed."""
    modules = {json.loads(x)["source"].split(":")[1].split("/")[0]
               for n in names for x in (MANIFESTS / n).read_text().splitlines() if x.strip()}
    missing = sorted(m for m in modules if importlib.util.find_spec(m) is None)
    if missing:
        pytest.skip(f"packages not installed (make real-objects): {missing}")


def test_sets_load_and_are_disjoint():
    _require_packages(*SETS)
    entries = {name: load_manifest(MANIFESTS / name) for name in SETS}
    ids = [{e.id for e in v} for v in entries.values()]
    shas = [{e.sha256 for e in v} for v in entries.values()]
    assert not ids[0] & ids[1] and not shas[0] & shas[1]
    assert all(len(s) == len(v) for s, v in zip(shas, entries.values()))  # no object twice in a set
    # the original 14 development objects keep their entries (figures refer to them)
    first = [json.loads(x)["id"] for x in (MANIFESTS / SETS[0]).read_text().splitlines()[:14]]
    assert first[0] == "pybullet_data__duck" and first[13] == "metaworld__hammer__hammerhead"


@pytest.mark.parametrize("name", SETS)
def test_entries_match_the_installed_bytes(name):
    _require_packages(name)
    entries = load_manifest(MANIFESTS / name)
    for e in entries:
        assert hashlib.sha256(e.ref().read_bytes()).hexdigest() == e.sha256, e.id
