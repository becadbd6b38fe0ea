"""The names a record keeps of the EN 14363 processing: its version and the filter order.

They live apart from :mod:`railval.core.en14363` and :mod:`railval.core.filters` (which load
numba and scipy.signal when imported) so that whatever only records or compares them — a
sign-off's evidence manifest, ``railval signoff list``, ``railval audit verify`` — reads them
without loading the filters, and a verb checks its ``--order`` before it loads them. Both
modules re-export them; change them here.
"""

from __future__ import annotations

from numbers import Integral

from railval.core.errors import InvalidParameter

#: bump whenever the numbers the EN 14363 processing produces can change (enters result-cache
#: keys and sign-off manifests)
PROCESSING_VERSION = "en14363/2"
#: Butterworth prototype order N of the 20 Hz low-pass and the 0.4–10 Hz band-pass (the low-pass
#: has order N, the band-pass 2N; docs/validation.md, step 2)
DEFAULT_ORDER = 4


def check_order(order: int) -> int:
    """The Butterworth prototype order as int; raises InvalidParameter outside 1..10.

    Parameters
    ----------
    order : int
        numpy integers count (they register as :class:`numbers.Integral`); bool does not.

    Returns
    -------
    int

    Examples
    --------
    >>> check_order(np.int64(6))
    6
    """
    if isinstance(order, bool) or not isinstance(order, Integral) or not 1 <= int(order) <= 10:
        raise InvalidParameter(f"filter order must be an integer in 1..10, got {order!r}")
    return int(order)
