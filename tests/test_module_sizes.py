"""The package stays readable: few modules at its root, none over 600 lines, and
no function over 80 lines without a reason written above it (docs/architecture.md)."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "invsss"

MAX_ROOT_MODULES = 6
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80


def root_modules(package: Path) -> list[str]:
    """The ``.py`` files directly in ``package`` (its folders not counted)."""
    return sorted(p.name for p in package.glob("*.py"))


def long_modules(package: Path, limit: int = MAX_MODULE_LINES) -> list[str]:
    """``"path: N lines"`` for each module of ``package`` over ``limit`` lines."""
    out = []
    for path in sorted(package.rglob("*.py")):
        count = len(path.read_text().splitlines())
        if count > limit:
            out.append(f"{path.relative_to(package.parent)}: {count} lines")
    return out


def _body_lines(node) -> int:
    """Lines of a function's body, its docstring left out."""
    body = node.body
    has_doc = (isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
               and isinstance(body[0].value.value, str))
    start = (body[1].lineno if len(body) > 1 else node.end_lineno) if has_doc else body[0].lineno
    return node.end_lineno - start + 1


def long_functions(package: Path, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """``"path:line name (N lines)"`` for each function over ``limit`` lines whose
    definition (or first decorator) has no comment line right above it."""
    out = []
    for path in sorted(package.rglob("*.py")):
        source = path.read_text()
        lines = source.splitlines()
        for node in ast.walk(ast.parse(source)):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            count = _body_lines(node)
            first = (node.decorator_list[0].lineno if node.decorator_list else node.lineno) - 1
            reason = first > 0 and lines[first - 1].lstrip().startswith("#")
            if count > limit and not reason:
                out.append(f"{path.relative_to(package.parent)}:{node.lineno} {node.name} ({count} lines)")
    return out


def test_the_package_root_holds_few_modules():
    assert len(root_modules(PACKAGE)) <= MAX_ROOT_MODULES, root_modules(PACKAGE)


def test_no_module_is_over_600_lines():
    assert long_modules(PACKAGE) == []


def test_no_function_is_over_80_lines_without_a_reason():
    assert long_functions(PACKAGE) == []


@pytest.fixture
def planted(tmp_path):
    """A package with one long module, one long function and one long function with a reason."""
    package = tmp_path / "pkg"
    package.mkdir()
    body = "".join(f"    x{i} = {i}\n" for i in range(85))
    (package / "long_function.py").write_text(f'def long():\n    """Doc."""\n{body}')
    (package / "reasoned.py").write_text(f"# Over 80 lines, kept whole: a table.\ndef table():\n{body}")
    (package / "long_module.py").write_text("x = 1\n" * 601)
    for name in "abcde":
        (package / f"{name}.py").write_text("")
    return package


def test_the_checks_name_what_breaks_the_rules(planted):
    assert long_functions(planted) == ["pkg/long_function.py:1 long (85 lines)"]
    assert long_modules(planted) == ["pkg/long_module.py: 601 lines"]
    assert len(root_modules(planted)) == 8 > MAX_ROOT_MODULES
