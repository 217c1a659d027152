"""One module per paper figure or experiment, the CLI, plotting and the reproduction report."""

import jax

jax.config.update("jax_enable_x64", True)
