"""The package stays layered, without import-linter (which `make lint-imports` runs
on the same layers, `[tool.importlinter]` in pyproject.toml).

Every module's imports, lazy ones inside functions included, are read with `ast`;
each module of piecs_bayes belongs to the layer of its top-level package:

    cli > export > jobs > simulate > uncertainty > feedback
        > gcode | fit | compensate | decide | capability | msa > io > geometry
        > errors | _config | intervals

A module imports only its own package and the layers below it; siblings of one
layer (`gcode | fit | compensate`, `errors | _config`) do not import each other;
`piecs_bayes/__init__.py` imports only the bottom layer. Another package is used
through its face (`__init__.py`): no `from ..fit._robust import x`, no
`from ..fit import _helper`. No module is longer than `MAX_LINES`.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "piecs_bayes"
#: one concept per module: a module may grow past 600 lines when it is one concept,
#: not past this
MAX_LINES = 1500
#: imports of a `_private` name from a sibling module (a concept split over files that
#: share privates), each with its reason; at most 10
SIBLING_PRIVATE: dict[str, str] = {}
#: parameters: a public function (no leading underscore) takes at most PUBLIC_PARAMS,
#: any function at most ANY_PARAMS; more settings than that want an options object
PUBLIC_PARAMS = 10
ANY_PARAMS = 12

#: top to bottom; one entry per layer, siblings of a layer together
LAYERS: tuple[tuple[str, ...], ...] = (
    ("cli",),
    ("export",),
    ("jobs",),
    ("simulate",),
    ("uncertainty",),
    ("feedback",),
    ("gcode", "fit", "compensate", "decide", "capability", "msa"),
    ("io",),
    ("geometry",),
    ("errors", "_config", "intervals"),
)
RANK = {top: rank for rank, layer in enumerate(LAYERS) for top in layer}
BOTTOM = set(LAYERS[-1])


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute name of what `from <...> import` names (relative imports resolved)."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(name: str, path: Path) -> list[tuple[int, str, str | None]]:
    """`(line, target module, imported name or None)` for every import of piecs_bayes
    modules in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(name, is_package, node)
            out += [(node.lineno, target, a.name) for a in node.names]
    return [t for t in out if t[1] == "piecs_bayes" or t[1].startswith("piecs_bayes.")]


def _top(target: str, imported: str | None) -> str | None:
    """The top-level package (layer member) an import reaches; None for the root's face
    (`from piecs_bayes import InputError`: the root re-exports the bottom layer only)."""
    parts = target.split(".")
    if len(parts) > 1:
        return parts[1]
    if imported is not None and (PACKAGE / imported).with_suffix(".py").exists():
        return imported
    if imported is not None and (PACKAGE / imported / "__init__.py").exists():
        return imported
    return None


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def test_every_module_belongs_to_a_layer():
    tops = {name.split(".")[1] for name in _modules() if name != "piecs_bayes"}
    assert sorted(tops - set(RANK)) == [], f"layers: {LAYERS}"


def test_no_module_imports_a_higher_layer_or_a_sibling():
    bad = []
    for name, path in _modules().items():
        own = name.split(".")[1] if name != "piecs_bayes" else None
        for line, target, imported in _imports(name, path):
            top = _top(target, imported)
            if top is None or top == own:
                continue
            if own is None:
                ok = top in BOTTOM
            else:
                ok = own in RANK and top in RANK and RANK[top] > RANK[own]
            if not ok:
                what = f"{target}.{imported}" if imported else target
                why = "" if top in RANK else f" ({top!r} is in no layer)"
                bad.append(f"{path.relative_to(ROOT)}:{line}: {name} imports {what}{why}")
    assert bad == [], "\n".join(bad)


def test_other_packages_are_used_through_their_face():
    bad = []
    for name, path in _modules().items():
        own = name.split(".")[1] if name != "piecs_bayes" else None
        for line, target, imported in _imports(name, path):
            top = _top(target, imported)
            if top is None or top == own:
                continue
            # below the top-level package: piecs_bayes.fit.lsq.losses is fit's own
            private_module = any(_is_private(p) for p in target.split(".")[2:])
            private_name = (
                imported is not None and _is_private(imported) and imported != top  # _config
            )
            if private_module or private_name:
                what = f"from {target} import {imported}" if imported else f"import {target}"
                bad.append(f"{path.relative_to(ROOT)}:{line}: {name}: {what}")
    assert bad == [], "\n".join(bad)


def test_no_module_is_longer_than_the_limit():
    long = {
        str(p.relative_to(ROOT)): n
        for p in _modules().values()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert long == {}, f"modules over {MAX_LINES} lines"


def test_module_docstrings_are_short():
    # a module docstring says what the module is for and what it promises (STYLE.md,
    # "One idea per room"): at most 15 lines from its first line of text to its last;
    # the model, its derivation, the numbers measured and the history go to docs/
    most = 15
    long = {}
    for p in _modules().values():
        tree = ast.parse(p.read_text(encoding="utf-8"), filename=str(p))
        doc = ast.get_docstring(tree, clean=False)
        if doc and (n := len(doc.strip("\n").splitlines())) > most:
            long[str(p.relative_to(ROOT))] = n
    assert long == {}, f"module docstrings over {most} lines (move the rest to docs/): {long}"


def test_sibling_private_imports_are_few_and_named():
    """`from ._sibling import _name` between modules of one package: a concept split
    over files that share privates. Each allowed one is named with its reason."""
    found = {}
    for name, path in _modules().items():
        if path.name == "__init__.py":
            continue
        package = name.rsplit(".", 1)[0]
        for line, target, imported in _imports(name, path):
            if imported is None or not _is_private(imported) or target == name:
                continue
            if target.rsplit(".", 1)[0] == package and target in _modules():
                if not _modules()[target].name == "__init__.py":
                    found[f"{name} <- {target}.{imported}"] = f"{path.relative_to(ROOT)}:{line}"
    unnamed = sorted(set(found) - set(SIBLING_PRIVATE))
    assert unnamed == [], "\n".join(f"{found[k]}: {k}" for k in unnamed)
    assert len(SIBLING_PRIVATE) <= 10


def _parameter_counts():
    for name, path in _modules().items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                n -= 1 if a.args and a.args[0].arg in ("self", "cls") else 0
                yield f"{path.relative_to(ROOT)}:{node.lineno}: {name}.{node.name}", node.name, n


def test_settings_travel_as_objects():
    """No function takes more than ANY_PARAMS parameters, no public one more than
    PUBLIC_PARAMS: settings that travel together are a frozen dataclass."""
    bad = [
        f"{where} takes {n}"
        for where, fn, n in _parameter_counts()
        if n > ANY_PARAMS or (n > PUBLIC_PARAMS and not _is_private(fn))
    ]
    assert bad == [], "\n".join(bad)


def test_the_checks_see_imports():
    # the helpers themselves: a relative, a lazy and a root import are all found
    src = (
        "from ..fit._robust import _x\nfrom .. import errors\ndef f():\n    import piecs_bayes.io\n"
    )
    tree = ast.parse(src)
    nodes = [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]
    targets = [
        _resolve("piecs_bayes.export._report", False, n) if isinstance(n, ast.ImportFrom) else ""
        for n in nodes
    ]
    assert targets[:2] == ["piecs_bayes.fit._robust", "piecs_bayes"]
    assert _top("piecs_bayes", "errors") == "errors"
    assert _top("piecs_bayes.fit._robust", "_x") == "fit"
