"""Short functions and modules in `dpc_mjx/` (issue 25): a function (or method) spans at most
`MAX_FUNCTION_LINES` lines, a module at most `MAX_MODULE_LINES`, outside the few exceptions named
here with the reason each is kept whole (at most `MAX_EXCEPTIONS` of each kind).

Length: a function's last line minus its first plus one, as the ast reports them
(`end_lineno - lineno + 1`: from its `def` line, decorators not counted, to its last line);
a module's number of lines.
"""

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "dpc_mjx"
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 400
MAX_EXCEPTIONS = 3  # of each kind

# The one place for exceptions: "module/path.py:Qualified.name" -> why it is better kept whole.
LONG_FUNCTIONS: dict[str, str] = {}
# "module/path.py" -> why it is better kept whole.
LONG_MODULES: dict[str, str] = {}


def _modules() -> list[pathlib.Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _name(path: pathlib.Path) -> str:
    return path.relative_to(PACKAGE).as_posix()


def _functions(tree: ast.AST, prefix: str = ""):
    """(qualified name, length in lines) of every function and method, nested ones too."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            name = prefix + node.name
            if not isinstance(node, ast.ClassDef):
                yield name, node.end_lineno - node.lineno + 1
            yield from _functions(node, name + ".")
        else:
            yield from _functions(node, prefix)


def _function_lengths() -> dict[str, int]:
    lengths = {}
    for path in _modules():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for name, length in _functions(tree):
            lengths[f"{_name(path)}:{name}"] = max(length, lengths.get(f"{_name(path)}:{name}", 0))
    return lengths


def _module_lengths() -> dict[str, int]:
    return {_name(p): len(p.read_text(encoding="utf-8").splitlines()) for p in _modules()}


def test_the_package_is_found():
    assert (PACKAGE / "__init__.py").is_file()
    assert len(_modules()) > 50


def test_functions_are_at_most_80_lines():
    long = {k: n for k, n in _function_lengths().items() if n > MAX_FUNCTION_LINES}
    unexpected = {k: n for k, n in long.items() if k not in LONG_FUNCTIONS}
    assert not unexpected, (
        f"Functions over {MAX_FUNCTION_LINES} lines: {unexpected}. Split them into named steps "
        "(or, if one is better kept whole, name it in LONG_FUNCTIONS with the reason)."
    )


def test_modules_are_at_most_400_lines():
    long = {k: n for k, n in _module_lengths().items() if n > MAX_MODULE_LINES}
    unexpected = {k: n for k, n in long.items() if k not in LONG_MODULES}
    assert not unexpected, (
        f"Modules over {MAX_MODULE_LINES} lines: {unexpected}. Move a coherent role into its own "
        "module (or, if one is better kept whole, name it in LONG_MODULES with the reason)."
    )


@pytest.mark.parametrize(
    ("exceptions", "lengths", "limit"),
    [
        (LONG_FUNCTIONS, _function_lengths, MAX_FUNCTION_LINES),
        (LONG_MODULES, _module_lengths, MAX_MODULE_LINES),
    ],
    ids=["functions", "modules"],
)
def test_exceptions_are_few_explained_and_still_needed(exceptions, lengths, limit):
    assert len(exceptions) <= MAX_EXCEPTIONS, f"at most {MAX_EXCEPTIONS} exceptions: {exceptions}"
    found = lengths()
    for name, reason in exceptions.items():
        assert reason.strip(), f"{name}: say why it is kept whole"
        assert name in found, f"{name} is named as an exception but does not exist; remove it"
        assert found[name] > limit, (
            f"{name} is {found[name]} lines, within {limit}: remove it from the exceptions"
        )


def test_lengths_are_measured_as_the_ast_reports():
    source = "def f():\n    x = 1\n\n    return x\n\n\nclass C:\n    def g(self):\n        pass\n"
    found = dict(_functions(ast.parse(source)))
    assert found == {"f": 4, "C.g": 2}
