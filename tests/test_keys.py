"""Named random streams (mc.keys.stream): each name derives exactly the key the studies derived
with an inline fold_in offset before the table existed, so every study's draws are unchanged."""

import jax
import numpy as np
import pytest

from oaraim import mc

#: the inline derivations the table replaced: (name, index, literal fold_in data)
BEFORE = [("gps_epoch", 0, 0), ("bpp_towers", 0, 1), ("risk_geometry", 0, 0),
          ("risk_geometry", 7, 7), ("risk_table", 0, 2), ("risk_cross_check", 2, 1002),
          ("risk_rerun", 0, 1), ("risk_ramp", 2 * 3 + 1, 107)]


@pytest.mark.parametrize(("name", "index", "literal"), BEFORE)
def test_streams_reproduce_the_inline_keys(name, index, literal):
    key = jax.random.fold_in(jax.random.key(12345), 6)
    got = jax.random.key_data(mc.stream(key, name, index))
    want = jax.random.key_data(jax.random.fold_in(key, literal))
    np.testing.assert_array_equal(got, want)


def test_stream_is_jit_safe_and_names_unknown_streams():
    key = jax.random.key(3)
    f = jax.jit(lambda k, i: jax.random.key_data(mc.stream(k, "risk_ramp", i)))
    np.testing.assert_array_equal(f(key, 5), jax.random.key_data(jax.random.fold_in(key, 105)))
    with pytest.raises(KeyError, match="risk_table"):
        mc.stream(key, "risk_tabel")
