"""The shape of the package's code (the house rules in docs/contributing.md): functions short
enough to read, no catch-all ``utils`` modules, no ``assert`` on input."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "crowdstudy"

#: The longest a function in crowdstudy/ may be, in lines (decorators and docstring included).
MAX_FUNCTION_LINES = 120

#: The functions allowed past the limit, each with the reason written beside it in the code.
LONG_FUNCTIONS = {
    "crowdstudy/physics/collision_kernels.py:narrowphase_kernel",
    "crowdstudy/physics/linear.py:pcg_fused_kernel",
}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path.relative_to(PACKAGE.parent).as_posix(), ast.parse(path.read_text(encoding="utf-8"))


def _functions(tree):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            start = min([node.lineno] + [d.lineno for d in node.decorator_list])
            yield node.name, node.end_lineno - start + 1


def test_no_function_is_longer_than_the_limit():
    long = {
        f"{name}:{func}": lines
        for name, tree in _modules()
        for func, lines in _functions(tree)
        if lines > MAX_FUNCTION_LINES
    }
    assert set(long) - LONG_FUNCTIONS == set(), {k: v for k, v in long.items() if k not in LONG_FUNCTIONS}
    # an exception that is no longer long leaves the list
    assert LONG_FUNCTIONS <= set(long), LONG_FUNCTIONS - set(long)
    assert len(LONG_FUNCTIONS) <= 3


def test_each_long_function_says_why():
    for entry in LONG_FUNCTIONS:
        path, func = entry.split(":")
        source = (PACKAGE.parent / path).read_text(encoding="utf-8").splitlines()
        line = next(i for i, text in enumerate(source) if text.startswith(f"def {func}("))
        assert "longer than the" in " ".join(source[max(0, line - 4) : line]), entry


def test_no_utils_module():
    names = {p.stem for p in PACKAGE.rglob("*.py")} | {p.name for p in PACKAGE.rglob("*") if p.is_dir()}
    assert not names & {"utils", "util", "helpers", "misc"}, names & {"utils", "util", "helpers", "misc"}


def test_no_assert_statement_in_the_package():
    # input is checked with InvalidInputError naming the argument; assert vanishes under -O
    found = [
        f"{name}:{node.lineno}" for name, tree in _modules() for node in ast.walk(tree) if isinstance(node, ast.Assert)
    ]
    assert found == []
