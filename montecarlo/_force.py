"""The on-site force of the potential U(x) = a|x|^n, shared by the numba kernels (private)."""

from __future__ import annotations

from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _onsite_force(x: float, a: float, n: float) -> float:
    """-U'(x) = -a n |x|^(n-1) sign(x), with fast paths for integer n."""
    ax = abs(x)
    if n == 3.0:
        p = ax * ax * 3.0
    elif n == 4.0:
        p = ax * ax * ax * 4.0
    elif ax == 0.0:
        return 0.0
    else:
        p = n * ax ** (n - 1.0)
    return -a * p if x > 0.0 else a * p
