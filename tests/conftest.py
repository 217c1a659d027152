import gc

import jax
import pytest

from oaraim import data


@pytest.fixture(scope="session")
def shared_data(tmp_path_factory):
    """A folder holding every registry file at its name (``nav/brdc0010.22n``, ...), each got
    through ``oaraim.data`` the way a user's run gets it: from the ``OARAIM_DATA`` folder or
    ``../shared/data`` (checksum checked), else from the mirror URL in ``OARAIM_DATA`` or the
    public origins into the cache (checksum checked). When every file is in one data folder,
    that folder itself; otherwise a session folder of links to the verified copies.

    Skips when some file cannot be had, naming each file and why; fails instead under
    ``OARAIM_REQUIRE_DATA=1`` (CI), so a data-backed test never passes by not running.
    """
    names = list(data.registry())
    try:
        folder = data.data_dir()
        if folder is not None and all((folder / n).is_file() for n in names):
            failed = {}
            for name in names:
                try:
                    data.verified_local(name, folder / name)
                except data.DataUnavailable as exc:
                    failed[name] = str(exc)
        else:
            folder = tmp_path_factory.mktemp("shared_data")
            failed = data.link_folder(folder, names)
        where = data.where()
    except data.DataUnavailable as exc:  # OARAIM_DATA names neither a folder nor a URL
        failed, where = {"OARAIM_DATA": str(exc)}, "OARAIM_DATA"
    if failed:
        by_reason: dict = {}
        for name, reason in failed.items():
            by_reason.setdefault(reason, []).append(name)
        msg = (f"real GNSS files unavailable ({len(failed)} of {len(names)} failed; looked "
               f"in {where}): " + " | ".join(
                   r if r.startswith("data file ") else f"{', '.join(n)}: {r}"
                   for r, n in by_reason.items()))
        if data.data_required():
            pytest.fail(msg + " (OARAIM_REQUIRE_DATA=1)", pytrace=False)
        pytest.skip(msg)
    return folder


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
