import jax
import pytest

jax.config.update("jax_enable_x64", True)

from geometry.datafiles import data_dir, data_required  # noqa: E402


@pytest.fixture(scope="session")
def shared_data():
    """The real-data folder; skips without it, fails instead when OARAIM_REQUIRE_DATA=1."""
    d = data_dir()
    if d is None:
        msg = ("real GNSS files not found: set OARAIM_DATA or put shared/data beside the "
               "checkout")
        if data_required():
            pytest.fail(msg + " (OARAIM_REQUIRE_DATA=1)")
        pytest.skip(msg)
    return d
