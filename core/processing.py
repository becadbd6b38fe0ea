"""The names a record keeps of the EN 14363 processing: its version and the default filter order.

They live apart from :mod:`railval.core.en14363` and :mod:`railval.core.filters` (which load
numba and scipy.signal when imported) so that whatever only records or compares them — a
sign-off's evidence manifest, ``railval signoff list``, ``railval audit verify`` — reads them
without loading the filters. Both modules re-export them; change them here.
"""

from __future__ import annotations

#: bump whenever the numbers the EN 14363 processing produces can change (enters result-cache
#: keys and sign-off manifests)
PROCESSING_VERSION = "en14363/2"
#: Butterworth prototype order N of the 20 Hz low-pass and the 0.4–10 Hz band-pass (the low-pass
#: has order N, the band-pass 2N; docs/validation.md, step 2)
DEFAULT_ORDER = 4
