"""docs/configuration.md is generated from the config dataclasses and is current; every synthesis
field carries its explanation (the comment the page is made from)."""

from pathlib import Path

from datagen.pipeline.reference import field_docs, render
from datagen.synth.config import EnergyWeights, SynthConfig
from datagen.wrench.contact import ContactModel

PAGE = Path(__file__).resolve().parents[2] / "docs" / "configuration.md"


def test_the_page_is_current():
    assert PAGE.read_text() == render(), "run: python -m datagen.pipeline.reference docs/configuration.md"


def test_every_synthesis_field_is_explained():
    for cls in (SynthConfig, ContactModel, EnergyWeights):
        docs = field_docs(cls)
        missing = [f for f in cls.__dataclass_fields__ if not docs.get(f)]
        assert not missing, f"{cls.__name__}: fields without a comment: {missing}"


def test_comments_above_a_field_and_continuation_lines_are_read():
    from dataclasses import dataclass

    @dataclass
    class Example:
        # the block above
        # speaks of a
        a: int = 1
        b: int = 2  #: b's line
                    #: continues here
        c: int = 3

    assert field_docs(Example) == {"a": "the block above speaks of a", "b": "b's line continues here", "c": ""}
