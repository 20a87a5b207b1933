"""One comparison for the native vector envs against Gymnasium's SyncVectorEnv: the same structure and values,
bit for bit."""

from __future__ import annotations

import numpy as np


def assert_same(a, b, path: str = "") -> None:
    """Equal structure (keys, masks, dtypes, shapes) and values, bit for bit (a row of the batched kernel does
    not depend on the batch)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), (path, sorted(a), sorted(b))
        for k in a:
            assert_same(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert b.dtype == object and a.shape == b.shape, path
        for i, (x, y) in enumerate(zip(a, b)):
            assert (x is None) == (y is None), (path, i)
            if x is not None:
                assert_same(x, y, f"{path}[{i}]")
    else:
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape, (path, a.dtype, b.dtype, a.shape, b.shape)
        np.testing.assert_array_equal(a, b, err_msg=path)
