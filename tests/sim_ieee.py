"""The built-in simulator's step compiled with IEEE semantics, without the kernel's
floating-point freedoms (``railval.core.sim.kernel.KERNEL_FASTMATH``, docs/simulator.md
"Numerical scheme"): the reference the freedoms are checked against, and the runs that
expectations frozen before the freedoms were made from (tests/en_frozen.py)."""

from __future__ import annotations

import functools
from collections.abc import Iterator
from contextlib import contextmanager


@functools.cache
def ieee_run_kernel():
    """``run_kernel``'s own Python function compiled by numba without fastmath (not cached on
    disk: numba's cache index does not tell the two compilations apart); once per process."""
    from numba import njit

    from railval.core.sim import kernel

    return njit(cache=False)(kernel.run_kernel.py_func)


@contextmanager
def ieee_kernel() -> Iterator[None]:
    """Within the block, every simulation of this process (and of pools it forks) runs the IEEE
    step; the kernel with the freedoms is back afterwards."""
    from railval.core.sim import kernel

    fast = kernel.run_kernel
    kernel.run_kernel = ieee_run_kernel()
    try:
        yield
    finally:
        kernel.run_kernel = fast
