import gc

import jax
import pytest

from oaraim.data import data_dir, data_required  # noqa: E402


@pytest.fixture(scope="session")
def shared_data():
    """The real-data folder (``OARAIM_DATA`` folder or ../shared/data beside the checkout);
    skips without it, fails instead when OARAIM_REQUIRE_DATA=1."""
    d = data_dir()
    if d is None:
        msg = ("real GNSS files not found: set OARAIM_DATA or put shared/data beside the "
               "checkout")
        if data_required():
            pytest.fail(msg + " (OARAIM_REQUIRE_DATA=1)")
        pytest.skip(msg)
    return d


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Drop every compiled XLA executable after each test module.

    Each CPU executable holds ~3 memory mappings until its jit cache entry goes, and the kernel
    caps a process at vm.max_map_count = 65530 of them by default. One pytest process of the
    whole suite kept every executable and reached that cap at ~90 % of the suite (measured
    with /proc/PID/maps: 65,119 mappings at the crash): XLA's compiler then segfaults in
    backend_compile_and_load, far from any cause, in whatever test compiled next. With this
    the full run peaked at 24,678 mappings. Clearing only above 32,000 mappings was measured
    no faster (15 min 28 s against 14 min 48 s), so it clears after every module.
    """
    yield
    jax.clear_caches()
    gc.collect()
