"""oaraim: Monte Carlo RAIM, ARAIM and opportunistic ARAIM (GNSS + signals of opportunity).

The subpackages are ``oaraim.geometry`` (where transmitters are), ``oaraim.araim`` (what a
receiver computes), ``oaraim.mc`` (how many epochs are run), ``oaraim.studies`` (the papers'
figures) and ``oaraim.data`` (the real GNSS files); the app layer above the studies is
``oaraim.cli``, ``oaraim.execute``, ``oaraim.registry``, ``oaraim.report`` and
``oaraim.bench``. The source tree keeps the subpackages as the top-level folders
``geometry/ araim/ mc/ studies/``; ``pyproject.toml`` installs them here.

float64 is the toolkit's convention (integrity probabilities reach 1e-9, normal matrices are
ill-conditioned near the edge of availability), so importing any part of oaraim enables JAX's
64-bit mode, here and only here. It also turns on JAX's persistent compilation cache
(``OARAIM_JAX_CACHE``; ``oaraim/_compile_cache.py``), so a kernel compiles once per machine,
and, where JAX has run nothing yet, XLA:CPU flags that compile faster
(``_compile_cache.XLA_CPU_FLAGS``; a flag the user's ``XLA_FLAGS`` names is left as it is).
"""

import jax

jax.config.update("jax_enable_x64", True)

from oaraim import _compile_cache  # noqa: E402

_compile_cache.configure()  # JAX's persistent compilation cache (OARAIM_JAX_CACHE)
_compile_cache.use_faster_compiler_flags()  # XLA:CPU's quicker-compiling emitters

__version__ = "0.2.0"
