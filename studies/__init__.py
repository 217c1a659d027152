"""One module per paper figure or experiment and what they share (``base``, ``common``); the
command line, registry, report and bench are the app layer above (``oaraim.cli`` etc.)."""

if __name__ != "oaraim.studies":  # the source folder is importable from the checkout's root
    raise ImportError(f"import oaraim.studies, not {__name__}: the folder studies/ installs as "
                      "oaraim.studies (pip install -e .), which also enables JAX's float64 mode")

