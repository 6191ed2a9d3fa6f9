"""The two test tiers: every test in the slow set names the cheaper `make test` test that covers it.

`make test` leaves out tests marked ``slow`` (`make test-slow` runs them; CI runs both). A test may go
to the slow set only if a cheaper test of the same behaviour stays in `make test`. The mark says which:
``@pytest.mark.slow(cover="tests/test_e2e.py::test_report_and_files")`` (a string, or a tuple of them).
This test reads every test file and checks that each cover exists and is not slow itself.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent


def _slow_mark(decorator: ast.expr) -> ast.expr | None:
    """The decorator if it is ``pytest.mark.slow`` or ``pytest.mark.slow(...)``, else None."""
    node = decorator.func if isinstance(decorator, ast.Call) else decorator
    if isinstance(node, ast.Attribute) and node.attr == "slow":
        inner = node.value
        if isinstance(inner, ast.Attribute) and inner.attr == "mark":
            return decorator
    return None


def _tests_in(path: Path) -> dict[str, list[ast.expr]]:
    """Test function name -> its decorators, for the module-level tests of one file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("test"):
            out[node.name] = node.decorator_list
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets
        ):
            marks = node.value.elts if isinstance(node.value, (ast.List, ast.Tuple)) else [node.value]
            assert not any(_slow_mark(m) for m in marks), (
                f"{path.name}: a whole module in the slow set; mark each test with its cover instead"
            )
    return out


def _covers(mark: ast.expr, where: str) -> list[str]:
    assert isinstance(mark, ast.Call), f"{where}: pytest.mark.slow needs cover='tests/test_x.py::test_y'"
    kw = {k.arg: k.value for k in mark.keywords}
    assert "cover" in kw, f"{where}: pytest.mark.slow needs cover='tests/test_x.py::test_y'"
    value = ast.literal_eval(kw["cover"])
    covers = [value] if isinstance(value, str) else list(value)
    assert covers and all(isinstance(c, str) for c in covers), f"{where}: cover={value!r} is not test ids"
    return covers


def _check(files: dict[str, dict[str, list[ast.expr]]]) -> int:
    """Check every slow test of ``files`` (path -> test -> decorators); the number checked."""
    slow = {
        (f, name)
        for f, tests in files.items()
        for name, decorators in tests.items()
        if any(_slow_mark(d) for d in decorators)
    }
    for f, name in sorted(slow):
        mark = next(m for m in map(_slow_mark, files[f][name]) if m is not None)
        for cover in _covers(mark, f"{f}::{name}"):
            file, _, test = cover.partition("::")
            test = test.split("[")[0]
            assert file in files and test in files[file], f"{f}::{name}: its cover {cover} does not exist"
            assert (file, test) not in slow, f"{f}::{name}: its cover {cover} is in the slow set too"
    return len(slow)


def test_every_slow_test_names_a_fast_cover_that_exists():
    files = {p.relative_to(TESTS.parent).as_posix(): _tests_in(p) for p in sorted(TESTS.glob("test_*.py"))}
    assert _check(files) > 0, "no slow tests found: has the mark's spelling changed?"


@pytest.mark.parametrize(
    ("source", "message"),
    [
        ("@pytest.mark.slow\ndef test_long():\n    pass\n", "needs cover="),
        (
            "@pytest.mark.slow(cover='tests/test_bad.py::test_gone')\ndef test_long():\n    pass\n",
            "does not exist",
        ),
        (
            "@pytest.mark.slow(cover='tests/test_bad.py::test_other')\ndef test_long():\n    pass\n\n"
            "@pytest.mark.slow(cover='tests/test_bad.py::test_long')\ndef test_other():\n    pass\n",
            "in the slow set too",
        ),
        ("pytestmark = pytest.mark.slow(cover='x')\n", "a whole module"),
    ],
)
def test_the_check_sees_a_bad_cover(tmp_path, source, message):
    bad = tmp_path / "test_bad.py"
    bad.write_text("import pytest\n\n" + source)
    with pytest.raises(AssertionError, match=message):
        _check({"tests/test_bad.py": _tests_in(bad)})
