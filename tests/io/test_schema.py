"""The `evaluated` schema (schemas/evaluated.json) agrees with the columns datagen.eval adds, and
every declared column is documented."""

from __future__ import annotations

import pytest

from datagen.eval.table import EVAL_COLUMNS
from schemas import SchemaError, arrow_schema, check_version, columns


def test_evaluated_is_grasps_plus_the_eval_columns():
    grasps, ev = arrow_schema("grasps", nq=31), arrow_schema("evaluated", nq=31)
    assert ev.names == grasps.names + list(EVAL_COLUMNS)
    for name, (dtype, _) in EVAL_COLUMNS.items():
        assert ev.field(name).type == dtype, name
    for name in grasps.names:
        assert ev.field(name).type == grasps.field(name).type, name


@pytest.mark.parametrize("name", ["grasps", "evaluated", "failures"])
def test_every_column_is_documented_and_versioned(name):
    cols = columns(name)
    assert len({c["name"] for c in cols}) == len(cols)
    assert all(c["doc"].strip() for c in cols)
    schema = arrow_schema(name, nq=31)
    check_version(schema, name)
    with pytest.raises(SchemaError, match="expected"):
        check_version(schema, "grasps" if name != "grasps" else "failures")


@pytest.mark.parametrize("name", ["grasps", "evaluated", "failures"])
def test_names_carry_their_units(name):
    """A column with one unit ends with its suffix; a suffix is never used for another unit."""
    from schemas import UNIT_SUFFIXES

    for c in columns(name):
        unit = c.get("unit", "")
        if unit in UNIT_SUFFIXES:
            assert c["name"].endswith(UNIT_SUFFIXES[unit]), (c["name"], unit)
        else:
            assert not any(c["name"].endswith(s) for s in UNIT_SUFFIXES.values()), (c["name"], unit)
