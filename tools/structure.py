"""The structure check of docs/design.md: private names across files, import cycles, file sizes,
docstrings.

    python tools/structure.py            # report; exit status 1 if a rule is broken
    python tools/structure.py --json     # the numbers, for docs/design.md and the tests

It reads the package's source folders (``pyproject.toml``'s ``[tool.setuptools.package-dir]``)
with ``ast`` and imports nothing, so it also runs on a tree that does not import.

- A *private cross-file import* is a name starting with one underscore that one package module
  takes from another: ``from oaraim.araim.mhss import _project``, or ``mhss._project`` where
  ``mhss`` is an imported package module. Dunders (``__version__``) are not private. A
  package's ``__init__.py`` may gather its own private modules (``from oaraim.araim._x import
  y``: the module is private, the name is not), which is how a public face is built.
- An *import cycle* is a strongly connected component of the module graph with more than one
  module, where every import counts, also the ones inside functions ("lazy"), since a lazy
  import still ties the two modules together. ``import oaraim.x`` makes the importing module
  depend on ``oaraim/x`` only; the package ``__init__`` modules that just re-export are edges
  like any other.
- A *layer violation* is an import between layers that ``LAYERS`` does not allow (the table
  docs/design.md draws): each module belongs to one layer (``layer_of``), and a layer may import
  itself and the layers listed for it, nothing else.
- A *face bypass* is a module outside one of the ``FACED`` layers (``araim``, ``geometry``,
  ``readers``, ``sim``, ``mc``) that imports one of that layer's submodules (``from
  oaraim.araim.mhss import required_order``, ``from oaraim.araim import fde``) or reaches one
  through the package (``araim.mhss.required_order`` after ``from oaraim import araim``): the
  package's ``__init__`` is the only way in, so what another layer needs is exported there
  (``araim.required_order``). A submodule the face itself imports as a module and lists in
  ``__all__`` is a public namespace (``araim.error_models``, ``sim.measurement``) and may be
  used as one. Each finding names the import to write instead.
- The *largest file* is counted in lines; the rule is at most ``MAX_LINES``.
- The *widest public signature*: the most parameters of a public function or method of a
  public module (``self`` and ``cls`` not counted, ``*args`` and ``**kwargs`` one each),
  with the number of signatures above ``TARGET_PARAMETERS``; a ratchet fails the check when
  the widest exceeds ``MAX_PARAMETERS``.
- A *tracker reference* (the word issue and a number, or a number after "(#") in the
  package, the tests, tools, docs, results, README or CHANGELOG: a reader cannot see the
  tracker, so the text states the decision.
- *Shapes as types*: of the functions the ``araim`` and ``geometry`` faces export (the public
  kernels among them), how many have every parameter and the return annotated, and how many
  carry a ``jaxtyping`` array type (``Float[Array, "T L 3"]``, or a module-level alias of one);
  reported, and checked at run time by tests/test_shapes.py.
- An *undocumented* name is a public function or class at the top level of a public module, or
  a public method of such a class, without a docstring (``ast.get_docstring``). A module is
  public when no component of its dotted name starts with "_" (a package ``__init__`` counts
  as its package); a name is public when it does not start with "_" (dunders included, so
  ``__init__`` needs none).
"""

from __future__ import annotations

import argparse
import ast
import json
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the largest package file allowed, in lines (a file a reader can hold)
MAX_LINES = 700
#: the target for public signatures: at most this many parameters (inputs and options as
#: objects, docs/design.md)
TARGET_PARAMETERS = 8
#: the limit the check enforces: the target, reached (a wider public signature fails it)
MAX_PARAMETERS = TARGET_PARAMETERS
#: a tracker reference (the word issue or issues and a number, or "(#" and a number): code and
#: docs state the decision instead. A document version ("ICD Issue 2.0") is not one.
TRACKER_RE = re.compile(r"\bissues?\s+#?\d+\b(?![.]\d)|\(#\d+\)", re.IGNORECASE)
#: where tracker references are looked for besides the package: files and folders of the
#: repository, with the suffixes read
TRACKER_PLACES = ("tests", "tools", "docs", "results", "README.md", "CHANGELOG.md",
                  "mkdocs.yml")
TRACKER_SUFFIXES = (".py", ".md", ".yml", ".json", ".toml", ".txt")

#: layer -> the layers it may import (besides itself); docs/design.md draws this table
LAYERS = {
    "root": {"constants", "config"},            # oaraim/__init__, the compilation cache
    "constants": set(),                         # oaraim.constants: every physical constant
    "config": set(),                            # oaraim.config: settings read by several layers
    "batching": {"config"},                     # oaraim.batching: tiles, buckets, threads, stores
    "oracles": set(),                           # oaraim.reference*: NumPy/SciPy only
    "errors": {"constants"},                    # oaraim.errors: the error models, one home
    "readers": {"constants"},                   # the files: records and tables as arrays
    "geometry": {"readers", "errors", "constants", "batching"},
    "araim": {"geometry", "readers", "errors", "constants", "config", "batching"},
    "mc": {"config"},
    "sim": {"araim", "geometry", "readers", "errors", "constants", "mc", "batching"},  # mc: streams
    "data": {"readers"},                        # oaraim.data: the real files, checked
    "studies": {"araim", "geometry", "readers", "errors", "mc", "sim", "data", "constants",
                "config", "batching"},
    "app": {"studies", "araim", "geometry", "readers", "errors", "mc", "sim", "data",
            "constants", "config", "oracles", "batching"},  # cli, execute, registry, report
}
_SUBPACKAGE_LAYERS = ("readers", "geometry", "araim", "mc", "sim", "studies")
#: the layers whose package ``__init__`` is the only way in for every other layer
FACED = ("araim", "geometry", "readers", "errors", "sim", "mc")


def layer_of(module: str) -> str:
    """The layer of a dotted module name of the package (``oaraim.araim.mhss`` -> "araim")."""
    parts = module.split(".")
    if len(parts) == 1 or parts[1] == "_compile_cache":
        return "root"
    if parts[1] in _SUBPACKAGE_LAYERS:
        return parts[1]
    if parts[1] in ("constants", "config", "data", "batching", "errors"):
        return parts[1]
    if parts[1].startswith("reference"):
        return "oracles"
    return "app"


def package_dirs(root: Path = ROOT) -> dict[str, Path]:
    """Dotted package name -> its source folder, as pyproject.toml installs them."""
    cfg = tomllib.loads((root / "pyproject.toml").read_text())
    dirs = cfg["tool"]["setuptools"]["package-dir"]
    return {name: root / folder for name, folder in dirs.items()}


def modules(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file, for every .py file of the package (subfolders included)."""
    out = {}
    for pkg, folder in package_dirs(root).items():
        for path in sorted(folder.rglob("*.py")):
            rel = path.relative_to(folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            name = ".".join([pkg, *parts]) if parts else pkg
            out.setdefault(name, path)  # a subpackage's folder is also below its parent's
    return out


def _resolve(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def scan(root: Path = ROOT):
    """(edges, private, sizes): module -> imported package modules; the private cross-file
    imports as (module, line, text); module -> line count. ``scan.reaches`` (set by the call)
    holds every (module, line, target module, text) of an import of a package module or an
    attribute reach ``alias.sub`` to one, for ``face_bypasses``."""
    mods = modules(root)
    known = set(mods)

    def owner(name: str) -> str | None:  # the longest known module that is name or its prefix
        while name:
            if name in known:
                return name
            name = name.rpartition(".")[0]
        return None

    edges: dict[str, set[str]] = {m: set() for m in mods}
    private: list[tuple[str, int, str]] = []
    reaches: list[tuple[str, int, str, str]] = []
    sizes = {}
    for mod, path in mods.items():
        text = path.read_text()
        sizes[mod] = text.count("\n") + (0 if text.endswith("\n") else 1)
        tree = ast.parse(text, filename=str(path))
        is_pkg = path.name == "__init__.py"
        aliases: dict[str, str] = {}  # local name -> package module it names
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    tgt = owner(a.name)
                    if tgt and tgt != mod:
                        edges[mod].add(tgt)
                        reaches.append((mod, node.lineno, tgt, f"import {a.name}"))
                        if a.asname:
                            aliases[a.asname] = tgt
            elif isinstance(node, ast.ImportFrom):
                src = _resolve(node, mod, is_pkg)
                for a in node.names:
                    full = f"{src}.{a.name}"
                    if full in known:  # from package import module
                        if full != mod:
                            edges[mod].add(full)
                            reaches.append((mod, node.lineno, full, f"from {src} import {a.name}"))
                        aliases[a.asname or a.name] = full
                        continue
                    tgt = owner(src)
                    if tgt is None or tgt == mod:
                        continue
                    edges[mod].add(tgt)
                    reaches.append((mod, node.lineno, tgt, f"from {src} import {a.name}"))
                    if _is_private(a.name) and not _gathers(mod, is_pkg, tgt):
                        private.append((mod, node.lineno, f"from {src} import {a.name}"))
        used_as = {id(n.value): n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases
                    and f"{aliases[node.value.id]}.{node.attr}" in known):
                # ``araim.mhss.required_order``: the name used, if the reach is followed by one
                then = f".{used_as[id(node)]}" if id(node) in used_as else ""
                reaches.append((mod, node.lineno, f"{aliases[node.value.id]}.{node.attr}",
                                f"{node.value.id}.{node.attr}{then}"))
            if (isinstance(node, ast.Attribute) and _is_private(node.attr)
                    and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and aliases[node.value.id] != mod):
                tgt = aliases[node.value.id]
                if not _gathers(mod, is_pkg, tgt):
                    private.append((mod, node.lineno, f"{node.value.id}.{node.attr}"))
    scan.reaches = sorted(set(reaches))
    return edges, sorted(set(private)), sizes


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _gathers(mod: str, is_pkg: bool, target: str) -> bool:
    """A package __init__ taking a name from one of its own (private) modules."""
    return is_pkg and target.startswith(mod + ".")


def face_names(root: Path = ROOT) -> dict[str, set[str]]:
    """Faced package -> the names its ``__init__`` lists in ``__all__``."""
    mods = modules(root)
    out = {}
    for layer in FACED:
        face = f"oaraim.{layer}"
        out[face] = set()
        if face not in mods:
            continue
        out[face] = _listed(ast.parse(mods[face].read_text()))
    return out


def _listed(tree: ast.Module) -> set[str]:
    """The names of ``__all__ = [...]`` and ``__all__ += [...]`` at a module's top level."""
    out, tuples = set(), {}
    for node in tree.body:
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, ast.AugAssign) else [])
        if not hasattr(getattr(node, "value", None), "elts"):
            continue
        names = {e.value for e in node.value.elts if isinstance(e, ast.Constant)}
        for e in node.value.elts:  # ``*_LAZY_NAMES``: a tuple of names assigned above
            if isinstance(e, ast.Starred) and isinstance(e.value, ast.Name):
                names |= tuples.get(e.value.id, set())
        for x in targets:
            if getattr(x, "id", None) == "__all__":
                out |= names
            elif isinstance(x, ast.Name):
                tuples[x.id] = names
    return out


def namespaces(root: Path = ROOT) -> set[str]:
    """The submodules a faced package's ``__init__`` imports as modules under their own name
    and lists in ``__all__``: its public namespaces (``oaraim.araim.error_models``)."""
    mods = modules(root)
    out = set()
    for layer in FACED:
        face = f"oaraim.{layer}"
        if face not in mods:
            continue
        tree = ast.parse(mods[face].read_text())
        listed = _listed(tree)
        for node in tree.body:
            if isinstance(node, ast.ImportFrom) and node.module == face:
                out |= {f"{face}.{a.name}" for a in node.names
                        if a.asname is None and a.name in listed and f"{face}.{a.name}" in mods}
    return out


def face_bypasses(root: Path = ROOT) -> list[str]:
    """Every import or attribute reach of a ``FACED`` layer's submodule from outside that
    layer, as "module:line: what it wrote -> what to write"."""
    scan(root)
    public = namespaces(root)
    exported = face_names(root)
    out = []
    for mod, line, target, text in scan.reaches:
        layer = layer_of(target)
        if layer not in FACED or layer_of(mod) == layer:
            continue
        face = f"oaraim.{layer}"
        name = (text.rsplit(" import ", 1)[-1] if " import " in text
                else text.split(".")[1] if text.count(".") == 1 else text.split(".")[2])
        if target == f"{face}.{name}" and name in exported[face]:
            continue  # the face exports a name spelled like its module (araim.slopes)
        through_namespace = any(target == ns or target.startswith(ns + ".") for ns in public)
        if target == face or (through_namespace and not (
                text.startswith("from ") and name in exported[face])):
            continue  # a namespace's own names; a name the face exports comes from the face
        sub = target[len(face) + 1:]
        if (text.startswith(("from ", "import ")) and not target.endswith("." + name)
                or text.count(".") == 2):
            fix = (f"`from oaraim import {layer}` and `{layer}.{name}` (export {name} in "
                   f"{layer}/__init__.py if it is not there)")
        else:
            fix = (f"`from oaraim import {layer}` and `{layer}.NAME` for what it uses of "
                   f"{sub} (export each NAME in {layer}/__init__.py if it is not there)")
        out.append(f"{mod}:{line}: {text} -> {fix}")
    return out


def undocumented(root: Path = ROOT) -> list[str]:
    """Dotted names of the public functions, classes and methods without a docstring."""
    out = []
    defs = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)
    for mod, path in modules(root).items():
        if any(part.startswith("_") for part in mod.split(".")):
            continue
        for node in ast.parse(path.read_text(), filename=str(path)).body:
            if not isinstance(node, defs) or node.name.startswith("_"):
                continue
            if not ast.get_docstring(node):
                out.append(f"{mod}.{node.name}")
            if isinstance(node, ast.ClassDef):
                out.extend(f"{mod}.{node.name}.{sub.name}" for sub in node.body
                           if isinstance(sub, defs[:2]) and not sub.name.startswith("_")
                           and not ast.get_docstring(sub))
    return out


def signatures(root: Path = ROOT) -> list[tuple[int, str]]:
    """(parameters, dotted name) of every public function and public method of a public
    module, widest first (``undocumented``'s notion of public)."""
    out = []
    funcs = (ast.FunctionDef, ast.AsyncFunctionDef)
    for mod, path in modules(root).items():
        if any(part.startswith("_") for part in mod.split(".")):
            continue
        for node in ast.parse(path.read_text(), filename=str(path)).body:
            if isinstance(node, funcs) and not node.name.startswith("_"):
                out.append((_parameters(node, method=False), f"{mod}.{node.name}"))
            elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                out.extend((_parameters(sub, method=True), f"{mod}.{node.name}.{sub.name}")
                           for sub in node.body
                           if isinstance(sub, funcs) and not sub.name.startswith("_"))
    return sorted(out, key=lambda x: (-x[0], x[1]))


def _parameters(fn, method: bool) -> int:
    a = fn.args
    n = (len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None)
         + (a.kwarg is not None))
    static = any(getattr(d, "id", None) == "staticmethod" for d in fn.decorator_list)
    return n - 1 if method and not static and n else n


#: the faces whose exported functions carry shapes as types (tests/test_shapes.py checks them)
SHAPED_FACES = ("araim", "geometry")
#: a jaxtyping array type in an annotation's source (``Float[``, ``Int8[``, ``PRNGKeyArray``)
SHAPE_RE = re.compile(r"\b(?:Float|Real|Int|UInt|Bool|Shaped|Complex|Num|Inexact|Integer|Key)"
                      r"\d*\[|\bPRNGKeyArray\b")


def _exported_function(mods: dict[str, Path], module: str, name: str, depth: int = 0):
    """(module, FunctionDef) of what ``name`` in ``module`` is: a def, a name imported from
    another module of the package, or ``name = wrapper(fn)`` (``jax.jit``); None otherwise."""
    if depth > 5 or module not in mods:
        return None
    tree = ast.parse(mods[module].read_text())
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == name:
            return module, node, tree
        if (isinstance(node, ast.Assign) and any(getattr(t, "id", None) == name
                                                 for t in node.targets)
                and isinstance(node.value, ast.Call) and node.value.args
                and isinstance(node.value.args[0], ast.Name)):
            return _exported_function(mods, module, node.value.args[0].id, depth + 1)
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("oaraim"):
            for a in node.names:
                if (a.asname or a.name) == name:
                    if f"{node.module}.{a.name}" in mods:
                        return None  # a module (a namespace), not a function
                    return _exported_function(mods, node.module, a.name, depth + 1)
    return None


def _lazy_modules(mods: dict[str, Path], face: str, depth: int = 0) -> set[str]:
    """The modules whose names a face loads on first use (PEP 562): the strings of its
    ``__getattr__`` that name one of its submodules, or another face (whose own lazy modules
    then count: ``geometry`` hands the recording names on to ``readers``)."""
    if depth > 3 or face not in mods:
        return set()
    init = ast.parse(mods[face].read_text())
    out = set()
    for c in (c for f in init.body if isinstance(f, ast.FunctionDef) and f.name == "__getattr__"
              for c in ast.walk(f) if isinstance(c, ast.Constant) and isinstance(c.value, str)):
        if f"{face}.{c.value}" in mods:
            out.add(f"{face}.{c.value}")
        elif c.value in mods and c.value != face:
            out |= {c.value} | _lazy_modules(mods, c.value, depth + 1)
    return out


def shape_annotations(root: Path = ROOT) -> dict:
    """Per face of ``SHAPED_FACES``: the functions it exports (``__all__``; a name loaded on
    first use is looked up in the face's modules), how many are fully annotated and how many
    carry a jaxtyping array type, and the dotted names of those without one."""
    mods = modules(root)
    out = {}
    for layer in SHAPED_FACES:
        face = f"oaraim.{layer}"
        if face not in mods:
            continue
        lazy_modules = _lazy_modules(mods, face)
        found = {}
        for name in sorted(face_names(root)[face]):
            hit = _exported_function(mods, face, name)
            if hit is None and f"{face}.{name}" not in mods:
                hits = [h for m in sorted(lazy_modules & set(mods))
                        for h in [_exported_function(mods, m, name)] if h and h[0] == m]
                hit = hits[0] if len(hits) == 1 else None
            if hit is not None:
                found[name] = hit
        full, shaped, unshaped, unannotated = 0, 0, [], []
        for _, (mod, fn, tree) in sorted(found.items()):
            aliases = {t.id for node in tree.body if isinstance(node, ast.Assign)
                       and SHAPE_RE.search(ast.unparse(node.value))
                       for t in node.targets if isinstance(t, ast.Name)}
            a = fn.args
            params = [*a.posonlyargs, *a.args, *a.kwonlyargs,
                      *(x for x in (a.vararg, a.kwarg) if x is not None)]
            hints = [ast.unparse(x.annotation) for x in params if x.annotation is not None]
            if len(hints) == len(params) and fn.returns is not None:
                full += 1
            else:
                unannotated.append(f"{mod}.{fn.name}")
            text = " ".join(hints + ([ast.unparse(fn.returns)] if fn.returns else []))
            if SHAPE_RE.search(text) or any(re.search(rf"\b{x}\b", text) for x in aliases):
                shaped += 1
            else:
                unshaped.append(f"{mod}.{fn.name}")
        out[layer] = {"functions": len(found), "annotated": full, "shaped": shaped,
                      "names": sorted(found), "unshaped": unshaped,
                      "unannotated": unannotated}
    return out


def tracker_references(root: Path = ROOT) -> list[str]:
    """Every "issue N" / "(#N)" in the package and in ``TRACKER_PLACES``, as "file:line:
    text"."""
    files = {path for path in modules(root).values()}
    for place in TRACKER_PLACES:
        p = root / place
        if p.is_file():
            files.add(p)
        elif p.is_dir():
            files |= {f for f in p.rglob("*") if f.is_file() and f.suffix in TRACKER_SUFFIXES}
    out = []
    for path in sorted(files):
        try:
            text = path.read_text()
        except (UnicodeDecodeError, OSError):
            continue
        for i, line in enumerate(text.splitlines(), 1):
            m = TRACKER_RE.search(line)
            if m:
                out.append(f"{path.relative_to(root)}:{i}: {m.group(0)!r} -> name the decision "
                           f"(or the page that states it) instead")
    return out


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = [0]
    for start in sorted(edges):
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return sorted(out)


def report(root: Path = ROOT) -> dict:
    """The numbers: private cross-file imports, cycles, the largest files, undocumented names."""
    edges, private, sizes = scan(root)
    cyc = cycles(edges)
    layers = sorted(
        f"{a} ({layer_of(a)}) imports {b} ({layer_of(b)})"
        for a, bs in edges.items() for b in bs
        if layer_of(a) != layer_of(b) and layer_of(b) not in LAYERS.get(layer_of(a), ())
        and layer_of(b) != "root")
    largest = sorted(sizes.items(), key=lambda kv: -kv[1])
    sigs = signatures(root)
    return {
        "modules": len(sizes),
        "private_imports": [f"{m}:{line}: {text}" for m, line, text in private],
        "cycles": cyc,
        "layer_violations": layers,
        "largest": [[m, n] for m, n in largest[:10]],
        "over_max_lines": [[m, n] for m, n in largest if n > MAX_LINES],
        "max_lines": MAX_LINES,
        "undocumented": undocumented(root),
        "face_bypasses": face_bypasses(root),
        "widest_signature": list(sigs[0]) if sigs else [0, ""],
        "signatures_over_target": sum(n > TARGET_PARAMETERS for n, _ in sigs),
        "target_parameters": TARGET_PARAMETERS,
        "max_parameters": MAX_PARAMETERS,
        "over_max_parameters": [[name, n] for n, name in sigs if n > MAX_PARAMETERS],
        "tracker_references": tracker_references(root),
        "shape_annotations": shape_annotations(root),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print the numbers as JSON")
    args = ap.parse_args(argv)
    rep = report()
    if args.json:
        print(json.dumps(rep, indent=1))
    else:
        print(f"{rep['modules']} modules")
        print(f"private cross-file imports: {len(rep['private_imports'])}")
        for line in rep["private_imports"]:
            print("  " + line)
        print(f"import cycles (lazy imports counted): {len(rep['cycles'])}")
        for comp in rep["cycles"]:
            print(f"  {len(comp)} modules: " + " ".join(comp))
        print(f"layer violations: {len(rep['layer_violations'])}")
        for line in rep["layer_violations"]:
            print("  " + line)
        print(f"files above {MAX_LINES} lines: {len(rep['over_max_lines'])}")
        for m, n in rep["over_max_lines"]:
            print(f"  {m}: {n}")
        print(f"public functions, classes and methods without a docstring: "
              f"{len(rep['undocumented'])}")
        for name in rep["undocumented"]:
            print("  " + name)
        print(f"imports past a package's face ({', '.join(FACED)}): "
              f"{len(rep['face_bypasses'])}")
        for line in rep["face_bypasses"]:
            print("  " + line)
        n, name = rep["widest_signature"]
        print(f"widest public signature: {n} parameters ({name}); "
              f"{rep['signatures_over_target']} above the target of {TARGET_PARAMETERS}; "
              f"the check fails above {MAX_PARAMETERS}: {len(rep['over_max_parameters'])}")
        for name, n in rep["over_max_parameters"]:
            print(f"  {name}: {n} parameters: take the inputs or options as one object "
                  f"(araim.Sources, a frozen options type) instead of adding parameters")
        print(f"tracker references in code and docs: {len(rep['tracker_references'])}")
        for line in rep["tracker_references"]:
            print("  " + line)
        for layer, c in rep["shape_annotations"].items():
            print(f"shapes as types, {layer}: {c['shaped']} of {c['functions']} exported "
                  f"functions carry jaxtyping array types; {c['annotated']} fully annotated")
    broken = (rep["private_imports"] or rep["cycles"] or rep["layer_violations"]
              or rep["over_max_lines"] or rep["undocumented"] or rep["face_bypasses"]
              or rep["over_max_parameters"] or rep["tracker_references"])
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
