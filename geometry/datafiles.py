"""Where the real GNSS files are: ``OARAIM_DATA``, else ``../shared/data`` beside the checkout."""

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


def data_dir():
    """The data folder, or None if there is none (the toolkit then uses built-in skies)."""
    env = os.environ.get("OARAIM_DATA")
    if env:
        p = Path(env).expanduser()
        if not p.is_dir():
            raise ValueError(f"OARAIM_DATA={env!r} is not a folder; point it at the shared data "
                             "folder or unset it to use the built-in constellations")
        return p
    p = REPO_ROOT.parent / "shared" / "data"
    return p if p.is_dir() else None


def data_required() -> bool:
    """True when tests must fail rather than skip without the data (OARAIM_REQUIRE_DATA=1)."""
    return os.environ.get("OARAIM_REQUIRE_DATA", "") not in ("", "0")
