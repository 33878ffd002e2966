"""Function sizes: no public function takes more than 11 parameters, and no function runs past 150 lines.

A public function is a module-level function or a method of a module-level class, neither named
with a leading ``_``, or a special method (``__init__``, ``__call__``) of such a class: the way
the class is called.  ``self`` and ``cls`` are not counted; ``*args`` and ``**kwargs`` count one
each; a dataclass's fields are not parameters.  Related parameters travel together in a small
frozen dataclass (:class:`~zbuf_occlude.pipeline.CameraSphere`,
:class:`~zbuf_occlude.geometry.samples.ObjectProvenance`), and a long function is split into
named steps.  The length, from ``def`` to the function's last line, is checked for every
function, private and nested ones included.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import zbuf_occlude

PACKAGE = Path(zbuf_occlude.__file__).parent
#: The most parameters a public function takes.
MAX_PARAMETERS = 11
#: The most lines a function spans, from ``def`` to its end.
MAX_LINES = 150
#: Known exceptions ``(module, qualified name)``, each with its reason; the list may only shrink.
ALLOWED: dict[tuple[str, str], str] = {}

FunctionNode = ast.FunctionDef | ast.AsyncFunctionDef


def _is_public(name: str) -> bool:
    return not name.startswith("_") or (name.startswith("__") and name.endswith("__"))


def _parameter_count(fn: FunctionNode, *, method: bool) -> int:
    a = fn.args
    names = [p.arg for p in (*a.posonlyargs, *a.args)]
    count = len(names) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
    return count - 1 if method and names and names[0] in ("self", "cls") else count


def oversized(source: str, module: str = "<source>") -> list[tuple[str, int, str, str]]:
    """``(module, line, qualified name, what)`` of each function of ``source`` over the bounds: a public
    function or method with more than :data:`MAX_PARAMETERS` parameters, any function spanning more
    than :data:`MAX_LINES` lines."""
    found: list[tuple[str, int, str, str]] = []

    def visit(body: list[ast.stmt], prefix: str, public: bool, in_class: bool) -> None:
        for node in body:
            if isinstance(node, ast.ClassDef):
                visit(node.body, f"{prefix}{node.name}.", public and not node.name.startswith("_"), True)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + node.name
                count = _parameter_count(node, method=in_class)
                if public and _is_public(node.name) and count > MAX_PARAMETERS:
                    found.append((module, node.lineno, name, f"{count} parameters"))
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_LINES:
                    found.append((module, node.lineno, name, f"{lines} lines"))
                visit(node.body, f"{name}.", False, False)  # nested: private, lengths still count
            else:  # functions under if, try, with, for, while or match, at the same level
                blocks = [getattr(node, field, []) for field in ("body", "orelse", "finalbody")]
                blocks += [part.body for part in (*getattr(node, "handlers", []), *getattr(node, "cases", []))]
                for block in blocks:
                    visit(block, prefix, public, in_class)

    visit(ast.parse(source).body, "", True, False)
    return found


def _package_oversized() -> list[tuple[str, int, str, str]]:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        found += oversized(path.read_text(encoding="utf-8"), module)
    return found


def test_no_function_is_too_long_and_no_public_one_takes_too_many_parameters():
    found = _package_oversized()
    offenders = [f"{module}:{line} {name} ({what})" for module, line, name, what in found if (module, name) not in ALLOWED]
    assert not offenders, (
        f"group related parameters in a frozen dataclass (at most {MAX_PARAMETERS}), split long functions "
        f"(at most {MAX_LINES} lines):\n" + "\n".join(offenders)
    )


def test_allowed_exceptions_still_exist():
    found = {(module, name) for module, _, name, _ in _package_oversized()}
    assert not set(ALLOWED) - found, f"these are within bounds now: remove them from ALLOWED: {sorted(set(ALLOWED) - found)}"


def _function(name: str, parameters: str, body_lines: int = 1, indent: str = "") -> str:
    body = "".join(f"{indent}    x = {i}\n" for i in range(body_lines))
    return f"{indent}def {name}({parameters}):\n{body}"


#: One parameter over the limit, and as many as it allows.
OVER = ", ".join(f"p{i}" for i in range(MAX_PARAMETERS + 1))
AT_MOST = ", ".join(f"p{i}" for i in range(MAX_PARAMETERS))
TOO_MANY = f"{MAX_PARAMETERS + 1} parameters"


@pytest.mark.parametrize(
    "source, expected",
    [
        (_function("build", OVER), [(1, "build", TOO_MANY)]),
        (_function("build", "a, *args, " + ", ".join(f"k{i}" for i in range(MAX_PARAMETERS - 2)) + ", **kwargs"), [(1, "build", TOO_MANY)]),
        (_function("build", "a, /, b, *, " + ", ".join(f"k{i}" for i in range(MAX_PARAMETERS - 1))), [(1, "build", TOO_MANY)]),
        ("class Set:\n" + _function("draw", "self, " + OVER, indent="    "), [(2, "Set.draw", TOO_MANY)]),
        ("class Set:\n    @classmethod\n" + _function("make", "cls, " + OVER, indent="    "), [(3, "Set.make", TOO_MANY)]),
        ("import sys\nif sys.platform:\n" + _function("build", OVER, indent="    "), [(3, "build", TOO_MANY)]),
        ("async " + _function("fetch", OVER), [(1, "fetch", TOO_MANY)]),
        ("class Set:\n" + _function("__init__", "self, " + OVER, indent="    "), [(2, "Set.__init__", TOO_MANY)]),
        (_function("_helper", "", body_lines=150), [(1, "_helper", "151 lines")]),
        (_function("outer", "") + _function("inner", "", body_lines=150, indent="    "),
         [(1, "outer", "153 lines"), (3, "outer.inner", "151 lines")]),
        ("class _Private:\n" + _function("method", "self", body_lines=150, indent="    "), [(2, "_Private.method", "151 lines")]),
    ],
    ids=["one too many", "star args count one each", "positional-only and keyword-only", "method", "classmethod",
         "under an if", "async", "a constructor", "a long private function", "nested", "a method of a private class"],
)  # fmt: skip
def test_the_walker_finds_every_offender(source, expected):
    assert [(line, name, what) for _, line, name, what in oversized(source)] == expected


@pytest.mark.parametrize(
    "source",
    [
        _function("build", AT_MOST, body_lines=149),
        "class Set:\n" + _function("draw", "self, " + AT_MOST, indent="    "),
        "class Set:\n    @staticmethod\n" + _function("make", AT_MOST, indent="    "),
        _function("_build", OVER),
        "class _Set:\n" + _function("draw", "self, " + OVER, indent="    "),
        _function("outer", "") + _function("inner", OVER, indent="    "),
        "class Set:\n" + _function("__init__", "self, " + AT_MOST, indent="    "),
        "from dataclasses import dataclass\n\n@dataclass(frozen=True)\nclass Settings:\n"
        + "".join(f"    field_{i}: int = {i}\n" for i in range(200)),
    ],
    ids=["the most parameters, 150 lines", "self is not counted", "the most in a staticmethod", "a private function", "a private class",
         "a nested function", "an __init__ of the most", "a dataclass's fields are not parameters"],
)  # fmt: skip
def test_the_walker_lets_the_rest_be(source):
    assert oversized(source) == []
