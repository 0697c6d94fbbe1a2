"""Index-adds whose results do not depend on thread timing on CUDA.

On CUDA, ``index_add_`` (and the gradient of ``index_select``, which is an ``index_add_``) sums the
values sent to one index with atomic adds, in whatever order the threads arrive: float sums then
differ in their last bits from run to run, and the same seed gives different poses, which breaks
the project's determinism promise (`tests/synth/test_device.py`). ``index_put_`` with
``accumulate=True`` sorts the indices on CUDA (a stable sort) and sums each index's values in that
fixed order; advanced indexing's gradient goes through it too. On the CPU the plain operations are
sequential and already deterministic, so they are kept there (the CPU's rows are unchanged).
"""

from __future__ import annotations

import torch


def _sorted(x: torch.Tensor, sorted_sum: bool | None) -> bool:
    """Whether to sum in the sorted order: ``sorted_sum``, by default on every device but the CPU."""
    return x.device.type != "cpu" if sorted_sum is None else sorted_sum


def index_add(out: torch.Tensor, dim: int, index: torch.Tensor, src: torch.Tensor,
              sorted_sum: bool | None = None) -> torch.Tensor:
    """``out.index_add(dim, index, src)`` (a new tensor), summed in a fixed order on CUDA too.
    ``index (n,)`` long; ``src`` has ``out``'s shape except ``n`` along ``dim``. ``sorted_sum``:
    use the sorted accumulation (default: on every device but the CPU)."""
    if not _sorted(out, sorted_sum):
        return out.index_add(dim, index, src)
    return out.movedim(dim, 0).index_put((index,), src.movedim(dim, 0), accumulate=True).movedim(0, dim)


def index_rows(x: torch.Tensor, index: torch.Tensor, sorted_sum: bool | None = None) -> torch.Tensor:
    """``x.index_select(0, index)``: ``(n, ...)`` rows of ``x (R, ...)``, whose gradient is summed
    in a fixed order on CUDA too (advanced indexing's backward, not ``index_add_``'s atomics).
    ``sorted_sum`` as in `index_add`."""
    if not _sorted(x, sorted_sum):
        return x.index_select(0, index)
    return x[index]


def batch_rows(x: torch.Tensor, index: torch.Tensor, sorted_sum: bool | None = None) -> torch.Tensor:
    """``(T, W, ...)``: rows ``index (T, W)`` of each batch ``t`` of ``x (T, P, ...)``, i.e.
    ``x.gather(1, index)`` broadcast over the trailing dims, with a gradient summed in a fixed
    order on CUDA too (``gather``'s is a scatter-add). ``sorted_sum`` as in `index_add`."""
    if not _sorted(x, sorted_sum):
        return x.gather(1, index.reshape(index.shape + (1,) * (x.dim() - 2)).expand(index.shape + x.shape[2:]))
    return x[torch.arange(x.shape[0], device=x.device)[:, None], index]
