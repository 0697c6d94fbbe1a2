"""Fixtures for the objects tests: an isolated cache, a fast CoACD config, tiny meshes."""

import numpy as np
import pytest

from datagen.objects.config import ProcessConfig

# (every RNG is seeded by tests/conftest.py)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache root, also set as $DATAGEN_CACHE so nothing touches ~/.cache."""
    root = tmp_path / "cache"
    monkeypatch.setenv("DATAGEN_CACHE", str(root))
    return root


@pytest.fixture(scope="session")
def fast_cfg():
    """CoACD settings ~3x cheaper than the defaults (tests only)."""
    return ProcessConfig(coacd_threshold=0.1, coacd_preprocess_resolution=30,
                         coacd_mcts_iterations=60, coacd_mcts_nodes=10, coacd_resolution=1000)


@pytest.fixture(scope="session")
def box_obj():
    """OBJ text of a 10 x 6 x 4 cm box (outward faces), as bytes."""
    import trimesh

    m = trimesh.creation.box(bounds=np.array([(0, 0, 0), (0.1, 0.06, 0.04)], float))
    lines = ["v %r %r %r" % tuple(v) for v in m.vertices.tolist()]
    lines += ["f %d %d %d" % tuple(f) for f in (m.faces + 1).tolist()]
    return ("\n".join(lines) + "\n").encode()


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread():
    """Small tensors: one thread is as fast and does not fight other jobs for the 2 cores."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
