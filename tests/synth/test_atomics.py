"""No atomics-summing operations in synthesis: the GPU determinism guard that runs on the CPU.

On CUDA, ``index_add_``, ``scatter_add_``, a ``scatter_reduce`` that sums, and the gradients of
``index_select`` and ``gather`` add with atomics in whatever order the threads arrive; float
results then differ from run to run and the same seed gives different poses on a GPU. Such ops
entered the synthesis twice between GPU checks (`benchmarks/results/cuda_check.md`), unseen by a
CI without a GPU. This test records every torch call of small CPU syntheses (a
``TorchFunctionMode``) and fails on any of those operations that is not made by
`datagen/scatter.py` (whose fixed-order replacements the GPU check verified), naming the caller.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from torch.overrides import TorchFunctionMode

from datagen.hands import available_hands, load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.tasks import load_task

SUMS = {"index_add", "index_add_", "scatter_add", "scatter_add_", "index_reduce", "index_reduce_"}
SUM_REDUCES = {"scatter_reduce", "scatter_reduce_"}  # with reduce sum / mean / prod (amin, amax: any order)
GRAD_READS = {"index_select", "gather", "take_along_dim"}  # their gradients are scatter-adds
ALLOWED = str(Path("datagen") / "scatter.py")
TORCH_DIR = str(Path(torch.__file__).parent)


def _caller() -> str:
    f = sys._getframe(1)
    while f is not None and (f.f_code.co_filename.startswith(TORCH_DIR)
                             or f.f_code.co_name in ("__torch_function__", "_caller")):
        f = f.f_back
    return f"{f.f_code.co_filename}:{f.f_lineno}" if f is not None else "?"


class AtomicsRecorder(TorchFunctionMode):
    """Records ``(op, caller)`` of each atomics-summing call on floating tensors (see the module)."""

    def __init__(self):
        super().__init__()
        self.calls: list[tuple[str, str]] = []

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = getattr(func, "__name__", "")
        x = args[0] if args and isinstance(args[0], torch.Tensor) else kwargs.get("input")
        if isinstance(x, torch.Tensor) and x.is_floating_point():
            reduce = kwargs.get("reduce", args[4] if len(args) > 4 else None)
            src = args[3] if len(args) > 3 and isinstance(args[3], torch.Tensor) else kwargs.get("src")
            if (name in SUMS or (name in SUM_REDUCES and reduce in ("sum", "mean", "prod"))
                    or (name in GRAD_READS and torch.is_grad_enabled() and x.requires_grad)
                    or (name in SUMS and isinstance(src, torch.Tensor) and src.requires_grad)):
                where = _caller()
                if not where.replace("\\", "/").rsplit(":", 1)[0].endswith(ALLOWED.replace("\\", "/")):
                    self.calls.append((name, where))
        return func(*args, **kwargs)


def _target(scale: float, name: str) -> GraspTarget:
    mesh = trimesh.creation.cylinder(radius=0.35, height=1.0, sections=32)
    mesh.apply_scale(1 / np.linalg.norm(0.5 * mesh.extents))
    return GraspTarget.from_mesh(mesh, scale, name, grid_resolution=16)


@pytest.mark.parametrize("hand_name,task_name", [("shadow", "force_closure"), ("shadow", "turn_knob3"),
                                                 ("shadow", "turn_handle"), ("leap", "force_closure")])
def test_synthesis_makes_no_atomics_summing_call(hand_name, task_name):
    if hand_name not in available_hands():
        pytest.skip(f"{hand_name} assets not installed (`make hands`)")
    hand = load_hand(hand_name)
    targets = [_target(0.07, "a"), _target(0.09, "b")]  # two targets: the stacked grid queries
    from datagen.pipeline import resolve

    cfg = resolve(hand_name, task_name, preset="paper", flags={"synth": dict(
        iters=40, seeds_per_grasp=2, seed_select_iter=20, num_directions=16, seed=1)}).synth  # the task's block too
    rec = AtomicsRecorder()
    with rec:  # the mode is thread-local: 8 poses stay on this thread (no parts)
        res = synthesize(hand, targets, load_task(task_name), cfg, 4)
    assert res.grasp.shape[0] == 8
    # the recorder sees the operations: the allowed ones made by datagen.scatter are not listed,
    # and a call of index_add here is (the recorder's own check)
    with rec:
        torch.zeros(3).index_add(0, torch.tensor([0, 0]), torch.ones(2))
    assert rec.calls[-1][0] == "index_add" and rec.calls[-1][1].startswith(__file__)
    found = sorted(set(rec.calls[:-1]))
    assert not found, f"operations that sum with atomics on CUDA (use datagen.scatter): {found}"
