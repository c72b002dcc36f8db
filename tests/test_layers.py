"""The package's layers import only the layers below them, and so do their tests.

invsss is packaged by layer (README, "Where things are"): the forward model at the
bottom, the estimator and the file formats above it, the command line at the top.
:func:`layer_violations` reads every module's imports with :mod:`ast` (absolute and
relative, at the top or inside a function, where the lazy imports are) and names
each one that reaches a layer its own may not use. It runs on the real package,
and on copies with one forbidden import planted, to show that it can fail.

``tests/`` mirrors the package: ``tests/<folder>/`` tests one layer
(:data:`TEST_FOLDERS`) and may use that layer and the layers below it, through public
names. :func:`suite_violations` reads every file there (helpers and conftests too, the
code of child processes written as strings, and ``python -m invsss`` command lines)
and names each use of invsss that reaches a layer above the folder's, each import of
a private name (``from invsss.x import _y``; :data:`PRIVATE_ALLOWED` lists the few
still needed), each private name of another layer's module reached through an
attribute (``module._y``, ``monkeypatch.setattr(module, "_y", ...)``), and each import
of another test file. It runs on the real tests and on planted sources.
"""

from __future__ import annotations

import ast
import functools
import importlib
import shutil
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
PACKAGE = TESTS.parent / "invsss"

#: What each layer may import besides itself. The package's root ``__init__``
#: (``invsss``) counts as a layer of its own: importing it imports the forward
#: model, so only the layers above the estimator may.
ALLOWED = {
    "validation": set(),
    "forward": {"validation"},
    "runtime": {"validation"},
    # The reference shaders read the model table (which shader, which dispatch).
    "shaders": {"forward", "validation"},
    "torch": {"forward", "validation"},
    "estimator": {"forward", "runtime", "validation"},
    # runtime: ResultDir has a signal that ends the command at once release its lock
    # (runtime/interrupts.py's quit cleanups, standard library only).
    "io": {"forward", "runtime", "shaders", "validation"},
    "measurement": {"forward", "estimator", "validation"},
    # ``import invsss`` loads the forward model and nothing else (the rest is lazy),
    # after the command line's Ctrl-C guard (runtime/interrupts.py, standard library only).
    "invsss": {"forward", "runtime", "validation"},
}
#: Layers that may import anything but the command line.
ABOVE = {"sweeps", "scenes", "experiments"}  # experiments: the old name of sweeps, kept for one release
#: Layers that may import anything: the command line, and ``python -m invsss``.
TOP = {"cli", "__main__"}


def _layer(module: str, package: Path) -> str:
    """The layer of the dotted name ``module`` (``invsss.forward.params`` -> ``forward``).

    A layer is a folder of the package or a module at its root (``validation``);
    any other name under ``invsss`` (``invsss.__version__``) is the root ``__init__``.
    """
    parts = module.split(".")
    if len(parts) == 1:
        return "invsss"
    head = package / parts[1]
    if head.is_dir() or head.with_suffix(".py").is_file():
        return parts[1]
    return "invsss"


def _module(path: Path, package: Path) -> tuple[str, str]:
    """The dotted name of the module at ``path`` and the package its relative imports start from."""
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        name = ".".join(parts[:-1])
        return name, name
    name = ".".join(parts)
    return name, name.rsplit(".", 1)[0]


def _imports(tree: ast.AST, this_package: str):
    """``(line, dotted name)`` of every import of an invsss module in ``tree``, at any depth.

    ``this_package`` is the dotted package a relative import starts from.
    """
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = this_package.split(".")[: len(this_package.split(".")) - (node.level - 1)]
                start = ".".join(base + ([node.module] if node.module else []))
            else:
                start = node.module or ""
            # ``from . import x`` may name a module: count it as ``start.x``.
            names = [start] if node.module else [f"{start}.{alias.name}" for alias in node.names]
        else:
            continue
        for name in names:
            if name == "invsss" or name.startswith("invsss."):
                yield node.lineno, name


def layer_violations(package: Path) -> list[str]:
    """One line per import in ``package`` (the ``invsss`` folder) that breaks the layer rules.

    A module in a folder or root module with no rule is a violation too: a new layer
    needs its rule written here.
    """
    found = []
    for path in sorted(package.rglob("*.py")):
        module, this_package = _module(path, package)
        own = _layer(module, package)
        where = path.relative_to(package.parent).as_posix()
        known = own in ALLOWED or own in ABOVE or own in TOP
        if not known:
            found.append(f"{where}: layer {own!r} has no rule in tests/test_layers.py")
            continue
        for line, name in _imports(ast.parse(path.read_text(encoding="utf-8")), this_package):
            target = _layer(name, package)
            if target == own:
                continue
            if target == "cli" and own != "__main__" and own != "cli":
                found.append(f"{where}:{line}: imports {name}; only invsss/__main__.py may import cli/")
            elif own in ALLOWED and target not in ALLOWED[own]:
                allowed = ", ".join(sorted({own} | ALLOWED[own]))
                found.append(f"{where}:{line}: imports {name}; {own} may import only {allowed}")
    return found


# ------------------------------------------------------------------ the tests' layers

#: The package layer each folder of ``tests/`` tests. A file in ``tests/<folder>/`` (or in
#: a folder inside it, as ``tests/estimator/stages/``) may use that layer and the layers
#: it may import, directly or through another (:func:`reachable`).
TEST_FOLDERS = {
    "forward": "forward",
    "runtime": "runtime",
    "shaders": "shaders",
    "torch": "torch",
    "estimator": "estimator",
    "io": "io",
    "measurement": "measurement",
    "scenes": "scenes",
    "sweeps": "sweeps",
    "cli": "cli",
}
#: Folders whose files may use every layer: the files at the top of ``tests/`` test the
#: package as a whole (its layers, its module sizes, what ``import invsss`` loads), and
#: ``tests/scripts/`` tests the scripts in ``experiments/`` and the data they made,
#: which use every layer.
EVERY_LAYER = {"", "scripts"}

#: Private names of invsss that tests may still use, each with the file that defines it
#: and why (none today: the report's and the sweeps' parts the tests read are public).
PRIVATE_ALLOWED: set[str] = set()


def reachable(layer: str, package: Path = PACKAGE) -> set[str]:
    """``layer`` and every layer it may import, directly or through another."""
    every = set(ALLOWED) | ABOVE | TOP
    if layer in TOP:
        return every
    if layer in ABOVE:
        return every - TOP
    found, todo = set(), [layer]
    while todo:
        name = todo.pop()
        if name not in found:
            found.add(name)
            todo.extend(ALLOWED.get(name, ()))
    return found


def _is_module(dotted: str, package: Path) -> bool:
    """Whether ``dotted`` (``invsss.io.images``) names a module or folder of ``package``."""
    path = package.parent.joinpath(*dotted.split("."))
    return path.is_dir() or path.with_suffix(".py").is_file()


def _split(dotted: str, package: Path) -> tuple[str, str | None]:
    """``invsss.a.b.c`` as (the longest module of ``package`` it starts with, the name after it)."""
    parts = dotted.split(".")
    module, i = parts[0], 1
    while i < len(parts) and _is_module(f"{module}.{parts[i]}", package):
        module, i = f"{module}.{parts[i]}", i + 1
    return module, parts[i] if i < len(parts) else None


@functools.cache
def _eager_names(package: Path) -> dict[str, str]:
    """Name -> module of each ``from .x import name`` in the package's ``__init__``."""
    found = {}
    for node in ast.parse((package / "__init__.py").read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            for alias in node.names:
                found[alias.asname or alias.name] = f"invsss.{node.module}"
    return found


def _root_module(name: str, package: Path) -> str:
    """The module that defines ``invsss.<name>``, a name the package's ``__init__`` gives
    (``invsss.fit_pair`` -> ``invsss.estimator.fit``); the root itself for its own names."""
    if _is_module(f"invsss.{name}", package):
        return f"invsss.{name}"
    eager = _eager_names(package)
    if name in eager:
        return eager[name]
    value = getattr(importlib.import_module("invsss"), name, None)
    module = getattr(value, "__module__", None)
    return module if isinstance(module, str) and module.startswith("invsss.") else "invsss"


def _private(dotted: str) -> bool:
    return any(part.startswith("_") and not part.startswith("__") for part in dotted.split("."))


def _code_strings(tree: ast.AST):
    """The string constants in ``tree`` that are Python code importing invsss (a child
    process's script), parsed."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and "invsss" in node.value:
            try:
                code = ast.parse(node.value)
            except SyntaxError:
                continue
            if any(isinstance(n, (ast.Import, ast.ImportFrom)) for n in ast.walk(code)):
                yield node.lineno, code


def _is_test_module(dotted: str, tests: Path) -> bool:
    """Whether ``dotted`` (``tests.forward._lit_scenes``) names a file under ``tests``."""
    return tests.parent.joinpath(*dotted.split(".")).with_suffix(".py").is_file()


def _uses(tree: ast.AST, this_package: str, package: Path, tests: Path):
    """``(line, module, name, how)`` for each use of invsss or of a test module in ``tree``.

    ``module`` is a dotted module (``invsss.io.images``, ``tests.forward._lit_scenes``)
    and ``name`` what is taken from it (None for the module itself); ``how`` is
    ``"import"``, or ``"attribute"`` where a name bound to an invsss module by an import
    is followed through an attribute (``solve.run_solver``) or through a ``setattr``-like
    call that names the attribute as a string. A list holding ``"-m", "invsss"`` (a child
    process running the command line) is a use of ``invsss.__main__``. An import of a
    module by a bare name that starts with ``test_`` or ``_`` (a test file or helper
    found on ``sys.path``) is given with that name as ``module``.
    """
    aliases: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                top = alias.name.split(".")[0]
                if top == "invsss":
                    aliases[alias.asname or top] = alias.name if alias.asname else top
                if top in ("invsss", "tests") or top.startswith("test_") or _private(top):
                    yield node.lineno, alias.name, None, "import"
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = this_package.split(".")[: len(this_package.split(".")) - (node.level - 1)]
                start = ".".join(base + ([node.module] if node.module else []))
            else:
                start = node.module or ""
            top = start.split(".")[0]
            for alias in node.names:
                full = f"{start}.{alias.name}"
                if top == "invsss" and _is_module(full, package):
                    aliases[alias.asname or alias.name] = full
                    yield node.lineno, full, None, "import"
                elif top == "tests" and _is_test_module(full, tests):
                    yield node.lineno, full, None, "import"
                elif top in ("invsss", "tests") or top.startswith("test_") or _private(top):
                    yield node.lineno, start, alias.name, "import"
    for node in ast.walk(tree):
        if isinstance(node, (ast.List, ast.Tuple)):
            # [sys.executable, "-m", "invsss", ...]: the command line, run as a child process.
            words = [e.value if isinstance(e, ast.Constant) else None for e in node.elts]
            if any(a == "-m" and b == "invsss" for a, b in zip(words, words[1:])):
                yield node.lineno, "invsss.__main__", None, "import"
        if isinstance(node, ast.Attribute):
            chain, base = [], node
            while isinstance(base, ast.Attribute):
                chain.append(base.attr)
                base = base.value
            if isinstance(base, ast.Name) and base.id in aliases:
                yield (node.lineno, *_split(".".join([aliases[base.id], *reversed(chain)]), package), "attribute")
        elif isinstance(node, ast.Call) and len(node.args) >= 2:
            # setattr(module, "name", v), monkeypatch.setattr(module, "name", v), getattr, ...
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            target, attribute = node.args[:2]
            if (name in ("setattr", "delattr", "getattr", "hasattr") and isinstance(target, ast.Name)
                    and target.id in aliases and isinstance(attribute, ast.Constant)
                    and isinstance(attribute.value, str)):
                yield (node.lineno, *_split(f"{aliases[target.id]}.{attribute.value}", package), "attribute")
        if (isinstance(node, ast.Call) and node.args and isinstance(node.func, ast.Attribute)
                and node.func.attr in ("setattr", "delattr") and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str) and node.args[0].value.startswith("invsss.")):
            # monkeypatch.setattr("invsss.x.y", value)
            yield (node.lineno, *_split(node.args[0].value, package), "attribute")


def _folder_layer(folder: str) -> str | None:
    """The layer the tests in ``folder`` (``estimator/stages``) test: None for a folder
    whose files may use every layer, ``""`` for a folder with no rule."""
    head = folder.split("/")[0]
    return None if head in EVERY_LAYER else TEST_FOLDERS.get(head, "")


def _test_module_violation(module: str, layer: str | None, allowed: set[str], tests: Path) -> str | None:
    """What is wrong with importing the test module ``module``, if anything."""
    parts = module.split(".")
    if parts == ["tests"]:
        return None  # tests/__init__.py: the repository's paths
    if parts[0] != "tests":
        return f"imports {module} by a bare name; import it as tests.<folder>.{parts[0]}"
    if parts[-1].startswith("test_"):
        return f"imports {module}, another test file; shared helpers go in a helper module or a conftest"
    if layer is None or len(parts) < 3:
        return None if layer is None else f"imports {module}, a helper at the top of tests/ (any layer)"
    used = _folder_layer(parts[1])
    if used is None or used and used not in allowed:
        return f"imports {module}, a helper of tests/{parts[1]}/, whose layer is above this folder's"
    return None


def source_violations(source: str, where: str, folder: str, package: Path = PACKAGE,
                      tests: Path = TESTS, scripts: bool = True) -> list[str]:
    """One line per rule of the tests' layers that ``source`` breaks.

    ``where`` names the file in the lines; ``folder`` is its folder under ``tests/``
    (``""`` for ``tests/`` itself, ``estimator/stages``), which sets the layers it may use.
    With ``scripts``, the string constants that are Python code importing invsss (a
    child process's script) are read as part of the file.
    """
    layer = _folder_layer(folder)
    if layer == "":
        return [f"{where}: folder tests/{folder.split('/')[0]}/ has no rule in tests/test_layers.py"]
    allowed = reachable(layer or "cli", package)
    tree = ast.parse(source)
    this_package = ".".join(["tests", *filter(None, folder.split("/"))])
    uses = [(line, module, name, how, "") for line, module, name, how in _uses(tree, this_package, package, tests)]
    for line, code in _code_strings(tree) if scripts else ():
        uses += [(line, module, name, how, " (in a child's script)")
                 for _, module, name, how in _uses(code, "", package, tests) if module.split(".")[0] == "invsss"]
    found, reached = [], set()
    for line, module, name, how, note in sorted(uses, key=lambda use: (use[0], -len(use[1]) - len(use[2] or ""))):
        dotted = f"{module}.{name}" if name else module
        if module.split(".")[0] != "invsss":
            problem = _test_module_violation(module, layer, allowed, tests)
            if problem:
                found.append(f"{where}:{line}: {problem}")
            continue
        target = _layer(_root_module(name, package) if module == "invsss" and name else module, package)
        # An import of a private name is refused from any layer; reaching into a private
        # name of a module through an attribute (monkeypatch.setattr(solve, "_step", ...))
        # only from another layer's tests.
        if _private(dotted) and dotted not in PRIVATE_ALLOWED and (how == "import" or target != layer):
            found.append(f"{where}:{line}: uses {dotted}{note}, a private name of "
                         + ("invsss; import public names only" if how == "import" else f"layer {target!r}"))
        if module == "invsss" and not name:
            continue  # ``import invsss``: what counts is each name used through it
        if target not in allowed and (line, target) not in reached:
            reached.add((line, target))  # once a line: invsss.cli.main is invsss.cli too
            found.append(f"{where}:{line}: uses {dotted}{note}, of layer {target!r}, which layer {layer!r} "
                         f"(tests/{folder}/) may not use")
    return list(dict.fromkeys(found))


def suite_violations(tests: Path = TESTS, package: Path = PACKAGE) -> list[str]:
    """:func:`source_violations` of every Python file under ``tests``."""
    found = []
    for path in sorted(tests.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        folder = path.parent.relative_to(tests).as_posix()
        folder = "" if folder == "." else folder
        # This file's strings are planted sources, not a child's scripts.
        found += source_violations(path.read_text(encoding="utf-8"), path.relative_to(tests.parent).as_posix(),
                                   folder, package, tests, scripts=path.name != Path(__file__).name or folder != "")
    return found


def test_the_package_keeps_its_layers():
    assert layer_violations(PACKAGE) == []


def test_the_checker_reads_every_module():
    """Every layer with a rule has modules here, so no rule passes for want of files."""
    layers = {_layer(_module(path, PACKAGE)[0], PACKAGE) for path in PACKAGE.rglob("*.py")}
    assert layers >= set(ALLOWED) | ABOVE | TOP


def _copy(tmp_path: Path) -> Path:
    copy = tmp_path / "invsss"
    # The modules only: the checker reads nothing else.
    shutil.copytree(PACKAGE, copy, ignore=lambda folder, names: [
        n for n in names if not n.endswith(".py") and not (Path(folder) / n).is_dir() or n == "__pycache__"])
    return copy


def _plant(copy: Path, module: str, text: str) -> None:
    path = copy / module
    path.write_text(path.read_text(encoding="utf-8") + "\n\n" + text + "\n", encoding="utf-8")


@pytest.mark.parametrize(
    "module, planted, expected",
    [
        # The forward model reaching up into the estimator, lazily inside a function.
        ("forward/params.py", "def _fit():\n    from ..estimator import fit_pair\n    return fit_pair",
         "invsss/forward/params.py:"),
        # An absolute import of the file readers from the caches.
        ("runtime/interrupts.py", "import invsss.io.images", "imports invsss.io.images; runtime may"),
        # The estimator reading files.
        ("estimator/__init__.py", "from invsss.io import read_image", "estimator may import only"),
        # A reader calling the command line.
        ("io/writing.py", "from ..cli import report", "only invsss/__main__.py may import cli/"),
        # A sweep calling the command line.
        ("sweeps/sweep.py", "from ..cli import main", "only invsss/__main__.py may import cli/"),
        # ``import invsss`` pulling in the estimator eagerly.
        ("__init__.py", "from .estimator import fit_pair", "invsss may import only forward, invsss, runtime, validation"),
        # The torch twin using the estimator.
        ("torch/passes.py", "from .. import estimator", "imports invsss.estimator; torch may"),
    ],
)
def test_a_planted_import_across_the_layers_is_named(tmp_path, module, planted, expected):
    copy = _copy(tmp_path)  # a copy of the package, which passes (the first test)
    _plant(copy, module, planted)
    found = layer_violations(copy)
    assert len(found) == 1 and expected in found[0], found


def test_a_folder_without_a_rule_is_named(tmp_path):
    copy = _copy(tmp_path)
    (copy / "plugins").mkdir()
    (copy / "plugins" / "__init__.py").write_text("from ..forward import params\n", encoding="utf-8")
    assert layer_violations(copy) == ["invsss/plugins/__init__.py: layer 'plugins' has no rule in tests/test_layers.py"]


# ------------------------------------------------------------------ the tests' layers, tested


def test_the_tests_keep_their_layers():
    assert suite_violations() == []


def test_every_test_folder_has_a_rule_and_every_rule_a_folder():
    """No folder escapes the check for want of a rule, and no rule outlives its folder."""
    folders = {path.parent.relative_to(TESTS).parts[0] for path in TESTS.rglob("test_*.py")
               if path.parent != TESTS}
    assert folders == set(TEST_FOLDERS) | (EVERY_LAYER - {""})
    assert set(TEST_FOLDERS.values()) <= set(ALLOWED) | ABOVE | TOP


def test_the_allowed_private_names_are_still_used_and_still_private():
    """A name made public (or no longer imported) leaves the allow-list with it."""
    used = set()
    for path in TESTS.rglob("*.py"):
        if "__pycache__" not in path.parts and path.name != "test_layers.py":
            text = path.read_text(encoding="utf-8")
            used |= {name for name in PRIVATE_ALLOWED if name.rsplit(".", 1)[1] in text}
    assert used == PRIVATE_ALLOWED
    for name in PRIVATE_ALLOWED:
        module, attribute = name.rsplit(".", 1)
        assert hasattr(importlib.import_module(module), attribute), name


@pytest.mark.parametrize(
    "folder, source, expected",
    [
        # The planted test of the issue: a private name imported from another layer.
        ("forward", "from invsss.estimator.problem import _build\n",
         ["uses invsss.estimator.problem._build, a private name of invsss; import public names only",
          "uses invsss.estimator.problem._build, of layer 'estimator', which layer 'forward'"]),
        # A private name imported from the folder's own layer is refused too.
        ("io", "from invsss.io.images import _decode_colour\n",
         ["uses invsss.io.images._decode_colour, a private name of invsss; import public names only"]),
        # Reaching into another layer's module through an attribute: the estimator's solver
        # step patched from the command line's tests.
        ("cli", "from invsss.estimator import solve\n\ndef test_x(monkeypatch):\n"
                "    monkeypatch.setattr(solve, '_step', None)\n",
         ["uses invsss.estimator.solve._step, a private name of layer 'estimator'"]),
        ("cli", "import invsss.estimator.solve as solve_module\n\ndef test_x():\n    solve_module._init\n",
         ["uses invsss.estimator.solve._init, a private name of layer 'estimator'"]),
        # The root's names count as the layer that defines them.
        ("forward", "import invsss\n\ndef test_x():\n    invsss.render\n    invsss.fit_pair\n",
         ["uses invsss.fit_pair, of layer 'estimator', which layer 'forward'"]),
        # A layer above, lazily inside a test, and in a child process's script.
        ("estimator", "def test_x():\n    from invsss.io import read_image\n",
         ["uses invsss.io.read_image, of layer 'io', which layer 'estimator'"]),
        ("runtime", "CHILD = 'import invsss.cli\\ninvsss.cli.main([])\\n'\n",
         ["uses invsss.cli.main (in a child's script), of layer 'cli', which layer 'runtime'"]),
        # The command line run as ``python -m invsss`` from the sweeps' tests.
        ("sweeps", "import sys\nARGS = [sys.executable, '-m', 'invsss', 'sweep']\n",
         ["uses invsss.__main__, of layer '__main__', which layer 'sweeps'"]),
        # Another test file, by a bare name or through the package, and a helper from above.
        ("io", "from test_shader import device\n", ["imports test_shader by a bare name"]),
        ("io", "from tests.io.test_shader import device\n", ["imports tests.io.test_shader, another test file"]),
        ("forward", "from tests.io._pair_files import write_pair\n",
         ["imports tests.io._pair_files, a helper of tests/io/, whose layer is above this folder's"]),
        # A folder with no rule.
        ("plugins", "import invsss\n", ["folder tests/plugins/ has no rule in tests/test_layers.py"]),
    ],
    ids=["private-from-above", "private-own-layer", "patch-another-layer", "attribute-another-layer",
         "root-name-from-above", "lazy-import-from-above", "child-script", "python-m-invsss",
         "bare-test-module", "test-module", "helper-from-above", "folder-without-rule"],
)
def test_a_planted_test_breaking_the_rules_is_named(folder, source, expected):
    found = source_violations(source, f"tests/{folder}/test_planted.py", folder)
    assert len(found) == len(expected) and all(e in f for e, f in zip(expected, found)), found


@pytest.mark.parametrize(
    "folder, source",
    [
        # The layer itself and the layers below it, through public names.
        ("estimator", "import invsss\nfrom invsss.forward.params import SSSParams\n"
                      "from invsss.runtime import compile_cache\n"
                      "def test_x():\n    invsss.fit_pair\n    invsss.render\n"),
        # A private name of the folder's own layer, reached through its module (a white-box patch).
        ("estimator", "from invsss.estimator import solve\n\ndef test_x(monkeypatch):\n"
                      "    monkeypatch.setattr(solve, '_step', None)\n"),
        # A private name on the allow-list, and a helper of a folder below.
        ("cli", "from invsss.cli.report import parameter_lines\nfrom tests.forward._lit_scenes import lit_card\n"),
        # The files at the top test the package as a whole.
        ("", "from invsss.cli import main\nimport invsss.torch\n"),
    ],
    ids=["own-layer-and-below", "patch-own-layer", "allowed-private-and-helper-below", "top-any-layer"],
)
def test_what_the_rules_allow_passes(folder, source):
    assert source_violations(source, f"tests/{folder}/test_planted.py", folder) == []
