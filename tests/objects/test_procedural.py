import collections
import io

import pytest
import trimesh

from datagen.objects import procedural


def _mesh(obj):
    return trimesh.load(io.BytesIO(obj.obj_bytes), file_type="obj", process=False)


def test_same_seed_index_same_bytes_and_different_otherwise():
    for i in range(10):
        assert procedural.generate(3, i).obj_bytes == procedural.generate(3, i).obj_bytes
    assert procedural.generate(3, 0).obj_bytes != procedural.generate(4, 0).obj_bytes
    assert procedural.generate(3, 0).obj_bytes != procedural.generate(3, 1).obj_bytes


def test_every_family_is_drawn_and_is_a_closed_solid():
    mix = collections.Counter(procedural.family_of(0, i) for i in range(600))
    assert set(mix) == set(procedural.FAMILIES)
    assert min(mix.values()) >= 20  # roughly uniform: 40 expected per family
    first = {}
    for i in range(600):
        first.setdefault(procedural.family_of(0, i), i)
    for family, i in first.items():
        obj = procedural.generate(0, i)
        assert obj.family == family
        m = _mesh(obj)
        assert m.is_watertight, family
        assert m.volume > 0, family
        assert 0.03 <= m.extents.max() <= 0.35, (family, m.extents)  # metres, household sizes
        assert len(m.split(only_watertight=False)) == 1, family


@pytest.mark.parametrize("family,genus", [("mug", 1), ("torus", 1), ("can", 0)])
def test_topology_of_families(family, genus):
    i = next(i for i in range(200) if procedural.family_of(0, i) == family)
    assert _mesh(procedural.generate(0, i)).euler_number == 2 - 2 * genus


def test_negative_seed_is_rejected_with_a_message():
    with pytest.raises(ValueError, match="seed=-1"):
        procedural.generate(-1, 0)
