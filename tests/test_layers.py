"""The package's layers import only the layers below them.

invsss is packaged by layer (README, "Where things are"): the forward model at the
bottom, the estimator and the file formats above it, the command line at the top.
:func:`layer_violations` reads every module's imports with :mod:`ast` (absolute and
relative, at the top or inside a function, where the lazy imports are) and names
each one that reaches a layer its own may not use. It runs on the real package,
and on copies with one forbidden import planted, to show that it can fail.
"""

from __future__ import annotations

import ast
import shutil
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "invsss"

#: What each layer may import besides itself. The package's root ``__init__``
#: (``invsss``) counts as a layer of its own: importing it imports the forward
#: model, so only the layers above the estimator may.
ALLOWED = {
    "validation": set(),
    "forward": {"validation"},
    "runtime": {"validation"},
    "shaders": {"validation"},
    "torch": {"forward", "validation"},
    "estimator": {"forward", "runtime", "validation"},
    "io": {"forward", "shaders", "validation"},
    "measurement": {"forward", "estimator", "validation"},
    # ``import invsss`` loads the forward model and nothing else (the rest is lazy),
    # after the command line's Ctrl-C guard (runtime/interrupts.py, standard library only).
    "invsss": {"forward", "runtime", "validation"},
}
#: Layers that may import anything but the command line.
ABOVE = {"experiments", "scenes"}
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
        ("experiments/sweep.py", "from ..cli import main", "only invsss/__main__.py may import cli/"),
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
