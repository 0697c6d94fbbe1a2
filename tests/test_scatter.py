"""`datagen.scatter`: the sorted index-adds give what torch's index_add / index_select give.

On CUDA these paths replace atomic adds (whose float sums vary from run to run); their run-to-run
identity on a GPU is checked by `tests/synth/test_device.py`. Here the sorted path is forced on the
CPU and compared with the plain operations, values and gradients, on indices with many repeats.
"""

import pytest
import torch

from datagen.scatter import batch_rows, index_add, index_rows


@pytest.mark.parametrize("dim", [0, 1])
def test_sorted_index_add_equals_index_add(dim):
    g = torch.Generator().manual_seed(0)
    out = torch.randn((7, 3) if dim == 0 else (2, 7, 3), generator=g, dtype=torch.float64)  # 7 slots along dim
    idx = torch.randint(0, 7, (500,), generator=g)
    shape = list(out.shape)
    shape[dim] = 500
    src = torch.randn(*shape, generator=g, dtype=torch.float64, requires_grad=True)
    before = out.clone()
    want = out.index_add(dim, idx, src)
    got = index_add(out, dim, idx, src, sorted_sum=True)
    assert torch.allclose(got, want, rtol=0, atol=1e-12)
    assert torch.equal(out, before)  # a new tensor, like index_add (not index_add_)
    w = torch.randn(want.shape, generator=g, dtype=torch.float64)
    (gw,) = torch.autograd.grad((want * w).sum(), src)
    (gg,) = torch.autograd.grad((got * w).sum(), src)
    assert torch.equal(gw, gg)  # each source element's gradient is the weight at its index


def test_sorted_rows_equal_index_select_and_their_gradient_counts_repeats():
    g = torch.Generator().manual_seed(1)
    x = torch.randn(5, 4, generator=g, dtype=torch.float64, requires_grad=True)
    idx = torch.randint(0, 5, (300,), generator=g)
    rows = index_rows(x, idx, sorted_sum=True)
    assert torch.equal(rows, x.index_select(0, idx))
    rows.sum().backward()
    # d/dx of the sum of the gathered rows: each row of x counted as often as it was read
    assert torch.equal(x.grad, torch.bincount(idx, minlength=5)[:, None].double().expand(5, 4))


def test_sorted_batch_rows_equal_gather():
    g = torch.Generator().manual_seed(2)
    x = torch.randn(3, 6, 3, generator=g, dtype=torch.float64, requires_grad=True)
    idx = torch.randint(0, 6, (3, 10), generator=g)
    want = x.gather(1, idx[..., None].expand(3, 10, 3))
    for sorted_sum in (False, True):
        got = batch_rows(x, idx, sorted_sum=sorted_sum)
        assert torch.equal(got, want)
        (grad,) = torch.autograd.grad(got.sum(), x)
        # each row of each batch counted as often as that batch read it
        counts = torch.stack([torch.bincount(i, minlength=6) for i in idx]).double()
        assert torch.equal(grad, counts[..., None].expand(3, 6, 3))
