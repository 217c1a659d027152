"""Settings read by more than one layer (``mc`` and ``araim``), in one place.

The host-thread setting, read from the environment at each call (a test or a user may change
it between calls; nothing is cached), and the NumPy page advice of the command line
(``small_pages_for_numpy``).
"""

import os

#: environment variable of the host-thread setting
THREADS_ENV = "OARAIM_THREADS"
#: host threads when ``OARAIM_THREADS`` is not set: the 2 cores of this project's machines,
#: where two XLA programs side by side use both cores and one uses ~1.6 (docs/benchmarks.md)
DEFAULT_THREADS = 2


def default_threads() -> int:
    """Host threads over which a large batch is split (``oaraim.batching.map_threads``) and over
    which an in-process sweep computes chunks side by side (``mc.sweep.run_sweep``):
    ``OARAIM_THREADS``, else ``DEFAULT_THREADS`` (2). ``OARAIM_THREADS=1`` turns the split off.
    Results never depend on it.

    Raises:
      ValueError: ``OARAIM_THREADS`` is not a positive integer (the message says so).
    """
    v = os.environ.get(THREADS_ENV, str(DEFAULT_THREADS))
    try:
        n = int(v)
    except ValueError:
        raise ValueError(f"{THREADS_ENV} must be a positive integer, got {v!r}") from None
    if n < 1:
        raise ValueError(f"{THREADS_ENV} must be a positive integer, got {v!r}")
    return n


#: NumPy's own switch of its transparent-huge-page advice (read when NumPy is imported)
NUMPY_HUGEPAGE_ENV = "NUMPY_MADVISE_HUGEPAGE"


def small_pages_for_numpy() -> bool:
    """Turn off NumPy's transparent-huge-page advice for its large arrays in this process and
    the processes it starts (``NUMPY_MADVISE_HUGEPAGE=0``), unless ``NUMPY_MADVISE_HUGEPAGE``
    is set already; True when turned off. The ``oaraim`` command calls it at start.

    Why: a huge page must be a free 2 MiB block, and on a virtual machine whose host backs
    guest memory lazily (this project's machines) such blocks are often memory the guest has
    not touched yet, which costs up to ~13 ns a byte on first touch; small pages reuse memory
    freed a moment before. Measured in a fresh process: a 150 MB array filled in 0.4-1.9 s
    with huge pages, 0.06 s without; on the 1 x 1 deg availability map (0.7 GB of values)
    the result's assembly took 10 s with huge pages, ~1 s without. The heavy arrays of a run
    live in XLA's buffers, which this leaves alone. A no-op where NumPy lacks the switch (a
    hint, never a result)."""
    if os.environ.get(NUMPY_HUGEPAGE_ENV) is not None:
        return False
    os.environ[NUMPY_HUGEPAGE_ENV] = "0"  # for the processes it starts (reproduce's jobs)
    import numpy as np

    setter = getattr(getattr(getattr(np, "_core", None), "multiarray", None),
                     "_set_madvise_hugepage", None)
    if setter is None:
        return False
    setter(False)
    return True
