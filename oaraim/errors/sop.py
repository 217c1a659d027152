"""The receiver-side error model of terrestrial signals of opportunity (seed 004 Appendix A):
no ionosphere and no troposphere, only the SOP's own sigma_URA^S (sigma_URE^S for accuracy)
and an optional user term.

    C_int(l, l) = sigma_URA^S^2 + sigma_user^2,    C_acc(l, l) = sigma_URE^S^2 + sigma_user^2
"""

import jax.numpy as jnp


def sop_variances(sigma_ura_m, sigma_ure_m=None, sigma_user_m=0.0):
    """(var_int_m2, var_acc_m2) of terrestrial SOPs: sigma_URA^S^2 + sigma_user^2 and
    sigma_URE^S^2 + sigma_user^2; no ionosphere or troposphere (seed 004 App. A). Seed 004 gives
    no SOP sigma_URE: default sigma_URE^S = sigma_URA^S (DESIGN.md)."""
    sigma_ura_m = jnp.asarray(sigma_ura_m, jnp.float64)
    if sigma_ure_m is None:
        sigma_ure_m = sigma_ura_m
    user2 = jnp.asarray(sigma_user_m, jnp.float64) ** 2
    return sigma_ura_m**2 + user2, jnp.asarray(sigma_ure_m, jnp.float64) ** 2 + user2

