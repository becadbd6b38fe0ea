"""railval.core — pure computation: EN 14363 processing, the DynoTRAIN validation method,
curve-comparison metrics, the vehicle–track simulator and diagnosis.

Nothing in this package imports ``db`` or ``app`` or does file I/O.
"""
