"""The structure check (tools/structure.py): the rules of docs/design.md's "Layers" hold."""

import importlib.util
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def structure():
    spec = importlib.util.spec_from_file_location("structure", ROOT / "tools" / "structure.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def rep(structure):
    return structure.report()


def test_no_private_name_crosses_a_file(rep):
    assert rep["private_imports"] == []


def test_no_import_cycle_with_lazy_imports_counted(rep):
    assert rep["cycles"] == []


def test_every_import_follows_the_layers(rep, structure):
    """docs/design.md's layer table: e.g. araim never imports sim, mc or studies."""
    assert rep["layer_violations"] == []
    assert structure.layer_of("oaraim.araim.mhss.root") == "araim"
    assert structure.layer_of("oaraim.cli") == "app"
    assert structure.layer_of("oaraim.reference_mhss") == "oracles"
    assert "sim" not in structure.LAYERS["araim"] and "studies" not in structure.LAYERS["sim"]


def test_no_package_file_above_the_line_limit(rep):
    assert rep["over_max_lines"] == [], f"files above {rep['max_lines']} lines"


def test_every_public_function_class_and_method_has_a_docstring(rep):
    """What mkdocstrings renders says what it is (private modules and names,
    and dunders such as ``__init__``, are not asked)."""
    assert rep["undocumented"] == []


def test_the_check_finds_what_it_looks_for(structure, tmp_path):
    """On a made-up tree: a private import, a lazy-import cycle, a long file and a public
    function without a docstring are all found, and a package __init__ gathering its own
    private module is not a violation."""
    (tmp_path / "pyproject.toml").write_text(textwrap.dedent("""
        [tool.setuptools.package-dir]
        "pkg" = "pkg"
        "pkg.sub" = "sub"
    """))
    (tmp_path / "pkg").mkdir()
    (tmp_path / "sub").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("from pkg._impl import thing\n")
    (tmp_path / "pkg" / "a.py").write_text(
        "from pkg.sub import b\n\ndef f():\n    return b._hidden\n")
    (tmp_path / "pkg" / "_impl.py").write_text(
        "thing = 1\n\ndef in_a_private_module():\n    pass\n")
    (tmp_path / "pkg" / "c.py").write_text(textwrap.dedent('''
        class C:
            """Documented."""

            def __init__(self):
                pass

            def m(self):
                pass

            def _helper(self):
                pass
    '''))
    (tmp_path / "sub" / "__init__.py").write_text("")
    (tmp_path / "sub" / "b.py").write_text(
        "def g():\n    from pkg import a  # lazy, still an edge\n    return a\n"
        + "x = 0\n" * (structure.MAX_LINES + 1))
    rep = structure.report(tmp_path)
    assert rep["private_imports"] == ["pkg.a:4: b._hidden"]
    assert rep["cycles"] == [["pkg.a", "pkg.sub.b"]]
    assert [m for m, _ in rep["over_max_lines"]] == ["pkg.sub.b"]
    assert rep["undocumented"] == ["pkg.a.f", "pkg.c.C.m", "pkg.sub.b.g"]


def test_no_module_imports_past_a_package_face(rep):
    """araim, geometry, sim and mc are entered through their ``__init__`` only: a study, the
    app or another layer never imports one of their submodules (namespaces the face lists,
    such as ``araim.error_models``, excepted), and each finding names the import to write."""
    assert rep["face_bypasses"] == []


def test_the_face_rule_finds_every_way_past_a_face(structure, tmp_path):
    """On a made-up tree: a name imported from a submodule, a name the face exports imported
    through a namespace, and a submodule reached as an attribute of the package are found, each
    with the import to write; the face's own names, its namespaces, a namespace's own names and
    imports inside the layer are not."""
    (tmp_path / "pyproject.toml").write_text(textwrap.dedent("""
        [tool.setuptools.package-dir]
        "oaraim" = "oaraim"
        "oaraim.araim" = "araim"
        "oaraim.studies" = "studies"
    """))
    for folder in ("oaraim", "araim", "studies"):
        (tmp_path / folder).mkdir()
    (tmp_path / "oaraim" / "__init__.py").write_text("")
    (tmp_path / "araim" / "__init__.py").write_text(
        "from oaraim.araim import ns\nfrom oaraim.araim.core import f\nfrom oaraim.araim.ns import"
        " k\n__all__ = ['f', 'k', 'ns']\n")
    (tmp_path / "araim" / "core.py").write_text("from oaraim.araim.hidden import h\nf = h\n")
    (tmp_path / "araim" / "ns.py").write_text("g = 1\nk = 2\n")
    (tmp_path / "araim" / "hidden.py").write_text("h = 3\n")
    (tmp_path / "studies" / "__init__.py").write_text("")
    (tmp_path / "studies" / "a.py").write_text(textwrap.dedent("""
        from oaraim import araim
        from oaraim.araim import f, ns
        from oaraim.araim.core import f as f2
        from oaraim.araim.ns import g, k

        x = araim.hidden.h + araim.ns.g + ns.g + f + f2 + g + k
    """))
    found = structure.report(tmp_path)["face_bypasses"]
    assert [line.split(" -> ")[0] for line in found] == [
        "oaraim.studies.a:4: from oaraim.araim.core import f",
        "oaraim.studies.a:5: from oaraim.araim.ns import k",
        "oaraim.studies.a:7: araim.hidden.h",
    ]
    assert "`from oaraim import araim` and `araim.f`" in found[0]
    assert "`araim.h` (export h in araim/__init__.py" in found[2]


def test_public_signatures_take_at_most_eight_parameters(rep, structure):
    """Inputs and options travel as objects: no public function or method takes more than
    ``MAX_PARAMETERS`` = ``TARGET_PARAMETERS`` = 8 parameters (docs/design.md)."""
    assert rep["over_max_parameters"] == [], (
        "take the inputs or options as one object instead of adding parameters")
    n, name = rep["widest_signature"]
    assert n <= structure.MAX_PARAMETERS == structure.TARGET_PARAMETERS == 8 and name
    assert rep["signatures_over_target"] == 0


def test_no_tracker_references_in_code_and_docs(rep):
    """Code, tests, docs and results state decisions, not tracker numbers a reader cannot
    see."""
    assert rep["tracker_references"] == []


def test_signatures_and_tracker_references_are_counted(structure, tmp_path):
    """On a made-up tree: parameters counted without self (``*args``, ``**kwargs`` one each,
    a staticmethod's first argument counted), private names and modules left out; a tracker
    number found in code and docs, a document version ("ICD Issue 2.0") not."""
    (tmp_path / "pyproject.toml").write_text(textwrap.dedent("""
        [tool.setuptools.package-dir]
        "pkg" = "pkg"
    """))
    (tmp_path / "pkg").mkdir()
    (tmp_path / "docs").mkdir()
    tracker = "issue" + " 12"  # written apart so this file holds none
    (tmp_path / "pkg" / "__init__.py").write_text(textwrap.dedent(f'''
        def wide(a, b, /, c, *args, d, **kw):
            """Six (see {tracker})."""

        def _hidden(a, b, c, d, e, f, g, h, i, j):
            """Private."""

        class K:
            """A class."""

            def m(self, a, b):
                """Two."""

            @staticmethod
            def s(a, b, c):
                """Three."""
    '''))
    (tmp_path / "pkg" / "_private.py").write_text("def wider(a, b, c, d, e, f, g, h, i):\n"
                                                   "    pass\n")
    (tmp_path / "docs" / "page.md").write_text(
        "Galileo OS SIS ICD Issue 2.0 Table 59.\nDecided in (#" + "7).\n")
    assert structure.signatures(tmp_path) == [(6, "pkg.wide"), (3, "pkg.K.s"), (2, "pkg.K.m")]
    found = structure.tracker_references(tmp_path)
    assert [line.split(" -> ")[0] for line in found] == [
        "docs/page.md:2: '(#" + "7)'", f"pkg/__init__.py:3: '{tracker}'"]
