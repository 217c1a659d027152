"""Griffe extension: find ``oaraim.araim`` & co. in the folders ``pyproject.toml`` maps them to.

The source tree keeps ``geometry/ araim/ mc/ studies/`` at the top level and setuptools installs
them as ``oaraim.geometry``, ``oaraim.araim``, ... (``[tool.setuptools.package-dir]``). Griffe's
static analysis looks for ``oaraim/araim/`` and does not read that mapping (nor the editable
install's finder for subpackages), so this extension grafts each mapped folder, loaded
statically, under the ``oaraim`` package as soon as griffe has visited ``oaraim/__init__.py``.
It reads the mapping from ``pyproject.toml``, so it works in a fresh clone with or without an
install, and imports nothing of the toolkit. Used by ``mkdocs.yml``.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import griffe

ROOT = Path(__file__).resolve().parent.parent


def package_dirs(root: Path = ROOT) -> dict[str, Path]:
    """``{"oaraim.araim": root / "araim", ...}``: the subpackages mapped to other folders."""
    with open(root / "pyproject.toml", "rb") as fh:
        mapping = tomllib.load(fh)["tool"]["setuptools"]["package-dir"]
    return {name: root / folder for name, folder in mapping.items()
            if "." in name and Path(folder) != Path(*name.split("."))}


class PackageDir(griffe.Extension):
    """Graft the folders of ``[tool.setuptools.package-dir]`` under their parent package."""

    def on_module_members(self, *, node: Any, mod: griffe.Module, agent: Any,
                          **kwargs: Any) -> None:
        for name, folder in package_dirs().items():
            parent, _, child = name.rpartition(".")
            if mod.path != parent or child in mod.members:
                continue
            sub = griffe.load(folder.name, search_paths=[folder.parent],
                              docstring_parser=getattr(agent, "docstring_parser", None),
                              docstring_options=getattr(agent, "docstring_options", None),
                              modules_collection=mod.modules_collection,
                              resolve_aliases=False)
            mod.set_member(child, sub)
