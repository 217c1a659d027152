"""Settings read by more than one layer (``mc`` and ``araim``), in one place.

Only the host-thread setting lives here today. It is read from the environment at each call,
so a test or a user may change it between calls; nothing is cached.
"""

import os

#: environment variable of the host-thread setting
THREADS_ENV = "OARAIM_THREADS"
#: host threads when ``OARAIM_THREADS`` is not set: the 2 cores of this project's machines,
#: where two XLA programs side by side use both cores and one uses ~1.6 (docs/benchmarks.md)
DEFAULT_THREADS = 2


def default_threads() -> int:
    """Host threads over which a large batch is split (``araim.batching.map_threads``) and over
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
