"""Fixtures of the evaluation tests: the Shadow hand (loaded once) and a scratch directory."""

import pytest
import torch


@pytest.fixture(scope="session")
def shadow():
    from datagen.hands import load_hand

    torch.set_num_threads(1)
    return load_hand("shadow")


@pytest.fixture(scope="session")
def box_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("eval_boxes")
