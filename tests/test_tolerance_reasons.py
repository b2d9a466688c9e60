"""Every numerical tolerance in tests/ carries its reason (STYLE.md: "Every tolerance
has a comment saying why it is that number").

What counts as a tolerance, found with ``ast``:

- *keyword*: a keyword argument ``rel``, ``abs``, ``rtol``, ``atol`` or ``decimal`` of any
  call (``pytest.approx``, ``np.testing.assert_allclose``, ``np.allclose``, ``np.isclose``, ...),
  except a literal 0 (``rtol=0`` switches that part off: nothing is tolerated);
- *threshold*: inside an ``assert`` statement, an ordering comparison (``<``, ``<=``, ``>``,
  ``>=``) with a non-zero float literal among its operands (``assert err < 0.05``,
  ``assert np.all(ratio > 0.9)``), and ``np.testing.assert_array_less`` with a non-zero
  float literal among its arguments. Integer thresholds (counts, sizes) are not tolerances.

A tolerance has its reason when a comment (found with ``tokenize``; ``noqa``/``type:``/
``pragma`` markers do not count) sits on the line of the tolerance's value or on the line
directly above it, the latter either a comment line of its own or a line of the same
statement (the trailing comment of the previous statement explains that statement). For a threshold the tolerance's line is the line of its float literal.
A keyword whose value is a bare name (``rtol=VOLUME_RTOL``) may instead have its reason
at an assignment of that name in the same file (the "one tolerance helper" habit).

The test below enforces the rule for both kinds; ``python tests/test_tolerance_reasons.py``
prints the counts per file.
"""

from __future__ import annotations

import ast
import io
import sys
import tokenize
from dataclasses import dataclass
from pathlib import Path

import pytest

TOLERANCE_KEYWORDS = frozenset({"rel", "abs", "rtol", "atol", "decimal"})
ORDERING = (ast.Lt, ast.LtE, ast.Gt, ast.GtE)
NOT_A_REASON = ("noqa", "type:", "pragma", "fmt:")
TESTS = Path(__file__).parent


@dataclass(frozen=True, kw_only=True)
class Tolerance:
    line: int  # 1-based line of the tolerance's value
    kind: str  # "keyword" or "threshold"
    text: str  # the source of the tolerance's value, for the message
    has_reason: bool
    todo: bool  # its reason is a "TODO(tolerance)"


def comments_by_line(source: str) -> tuple[dict[int, str], set[int]]:
    """Comment text (without '#') per 1-based line, markers like ``noqa`` left out, and
    the lines that hold nothing but a comment."""
    comments, alone = {}, set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            text = token.string.lstrip("#").strip()
            if text and not text.lower().startswith(NOT_A_REASON):
                comments[token.start[0]] = text
                if not token.line[: token.start[1]].strip():
                    alone.add(token.start[0])
    return comments, alone


def _nonzero_floats(node: ast.AST) -> list[ast.Constant]:
    """Non-zero float literals of an operand, not looking into calls: in
    ``eigvalsh(0.5 * (C + C.T)) > 0`` or ``abs(ratio - 1.0) < 0.05`` only the 0.05 is a
    threshold."""
    if isinstance(node, ast.Call):
        return []
    if isinstance(node, ast.Constant):
        return [node] if type(node.value) is float and node.value != 0.0 else []
    return [c for child in ast.iter_child_nodes(node) for c in _nonzero_floats(child)]


def _call_name(call: ast.Call) -> str:
    func = call.func
    return func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")


def find_tolerances(source: str) -> list[Tolerance]:
    """All tolerances in one test file's source, in line order."""
    tree = ast.parse(source)
    comments, alone = comments_by_line(source)
    statements = sorted(
        ((node.lineno, node.end_lineno) for node in ast.walk(tree) if isinstance(node, ast.stmt)),
        key=lambda span: span[1] - span[0],
    )

    def reason_at(line: int, statement_start: int) -> str | None:
        """The comment on ``line``, or on the line above when that line is a comment of its
        own or belongs to the same statement (a trailing comment of the previous statement
        explains that statement, not this one)."""
        above = line - 1
        if line in comments:
            return comments[line]
        if above in comments and (above in alone or above >= statement_start):
            return comments[above]
        return None

    def statement_start(line: int) -> int:
        return next((start for start, end in statements if start <= line <= end), line)
    found: dict[tuple[int, int], tuple[str, str]] = {}  # (line, column) -> (kind, text)

    def add(kind: str, node: ast.AST) -> None:
        found[(node.lineno, node.col_offset)] = (kind, ast.unparse(node))

    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            for keyword in node.keywords:
                value = keyword.value
                if keyword.arg in TOLERANCE_KEYWORDS and not (isinstance(value, ast.Constant) and value.value == 0):
                    add("keyword", value)
            if _call_name(node) == "assert_array_less":
                for constant in (c for arg in node.args for c in _nonzero_floats(arg)):
                    add("threshold", constant)
        if isinstance(node, ast.Assert):
            for compare in ast.walk(node.test):
                if isinstance(compare, ast.Compare) and any(isinstance(op, ORDERING) for op in compare.ops):
                    operands = [compare.left, *compare.comparators]
                    for operand in operands:
                        for constant in _nonzero_floats(operand):
                            add("threshold", constant)

    named_reasons = {}  # name -> reason comment at one of its assignments
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            reason = reason_at(node.lineno, node.lineno)
            if reason:
                named_reasons[node.targets[0].id] = reason

    tolerances = []
    for (line, _), (kind, text) in sorted(found.items()):
        reason = reason_at(line, statement_start(line))
        if reason is None and kind == "keyword" and text.isidentifier():
            reason = named_reasons.get(text)
        tolerances.append(
            Tolerance(
                line=line,
                kind=kind,
                text=text,
                has_reason=reason is not None,
                todo=bool(reason) and "TODO(tolerance)" in reason,
            )
        )
    return tolerances


def sources() -> list[Path]:
    return sorted(TESTS.glob("*.py"))


# -- the rule, checked on synthetic sources first so that it can fail ------------------

SYNTHETIC = '''\
import numpy as np
import pytest

def test_a():
    assert x == pytest.approx(1.0, rel=1e-9)  # float64 round-off
    # P2 elements: O(h^3) discretisation error at this mesh
    np.testing.assert_allclose(a, b, rtol=1e-3)
    assert y == pytest.approx(2.0, abs=1e-6)
    np.testing.assert_allclose(
        a,
        b, rtol=0,
        atol=1e-12,  # noqa: E501
    )
    assert err < 0.05
    assert n_points > 3
    assert np.all(err <= 1e-3)  # 3 sigma of the 0.3e-3 noise
    assert 0.0 < ratio  # a sign, not a tolerance
    assert np.linalg.eigvalsh(0.5 * (C + C.T))[0] > 0 and abs(ratio - 1.0) < 0.05
    np.testing.assert_array_less(err, 2.0 * conf)
    assert np.isclose(
        a,
        b,  # data written with 6 significant digits
        rtol=1e-6,
    )
'''


def test_finds_every_kind_of_tolerance_in_a_synthetic_file():
    tolerances = find_tolerances(SYNTHETIC)
    summary = [(t.line, t.kind, t.text, t.has_reason) for t in tolerances]
    assert summary == [
        (5, "keyword", "1e-09", True),
        (7, "keyword", "0.001", True),
        (8, "keyword", "1e-06", False),
        (12, "keyword", "1e-12", False),  # a noqa marker is not a reason
        (14, "threshold", "0.05", False),
        (16, "threshold", "0.001", True),
        (18, "threshold", "0.05", False),
        (19, "threshold", "2.0", False),
        (23, "keyword", "1e-06", True),
    ]


def test_a_named_tolerance_may_carry_its_reason_where_it_is_defined():
    source = (
        "# OCC integrates planes and cylinders to round-off\n"
        "VOLUME_RTOL = 1e-9\n"
        "BOX_ATOL = 1e-6\n"
        "assert v == pytest.approx(w, rel=VOLUME_RTOL)\n"
        "assert v == pytest.approx(w, abs=BOX_ATOL)\n"
    )
    assert [(t.line, t.has_reason) for t in find_tolerances(source)] == [(4, True), (5, False)]


def test_a_todo_counts_as_a_reason_but_is_flagged():
    source = "assert e < 0.1  # TODO(tolerance): noise level of this rig unknown\n"
    (tolerance,) = find_tolerances(source)
    assert tolerance.has_reason and tolerance.todo


def test_counts_every_tolerance_once():
    source = "assert a < 0.5 and b < 0.5 < c\nassert x == pytest.approx(y, rel=1e-3, abs=1e-9)\n"
    found = [(t.line, t.text) for t in find_tolerances(source)]
    assert found == [(1, "0.5"), (1, "0.5"), (2, "0.001"), (2, "1e-09")]


# -- the rule on the real tests ---------------------------------------------------------


@pytest.mark.parametrize("path", sources(), ids=lambda p: p.name)
def test_every_tolerance_has_a_reason(path):
    missing = [t for t in find_tolerances(path.read_text()) if not t.has_reason]
    assert not missing, "tolerances without a reason comment (same line or the line above):\n" + "\n".join(
        f"  {path.name}:{t.line}: {t.kind} {t.text}" for t in missing
    )


def main() -> None:
    """Print tolerances with / without a reason per file and in total."""
    totals = {"keyword": [0, 0], "threshold": [0, 0]}
    n_todo = 0
    for path in sources():
        tolerances = find_tolerances(path.read_text())
        if not tolerances:
            continue
        for t in tolerances:
            totals[t.kind][0] += t.has_reason
            totals[t.kind][1] += 1
            n_todo += t.todo
        n_reason = sum(t.has_reason for t in tolerances)
        print(f"{path.name:36s} {n_reason:4d} / {len(tolerances):4d}")
    for kind, (n_reason, n) in totals.items():
        print(f"{kind:36s} {n_reason:4d} / {n:4d}")
    n_reason = sum(v[0] for v in totals.values())
    n = sum(v[1] for v in totals.values())
    print(f"{'all':36s} {n_reason:4d} / {n:4d}   (of which TODO(tolerance): {n_todo})")
    if "-v" in sys.argv:
        for path in sources():
            for t in find_tolerances(path.read_text()):
                if not t.has_reason:
                    print(f"{path.name}:{t.line}: {t.kind} {t.text}")


if __name__ == "__main__":
    main()
