"""The package's layering, read statically from its source (DESIGN.md "The parts and their seams").

Every module of ``sns_np`` is parsed with ``ast``; every ``import`` and ``from ... import``
counts, at module level or inside a function or class (a deferred import is still a
dependency), with relative imports resolved against the importing module. The unit of the
layering is a subpackage (``sns_np/geometry/``) or a top-level module (``sns_np/sampling.py``).
Checked:

* no cycle between units;
* no forbidden direction (:data:`FORBIDDEN`);
* no private name crosses a unit: neither a module with a leading underscore
  (``sns_np.geometry._common``) nor a name with one (``from sns_np.sampling import _x``),
  nor an attribute with one of a module imported from another unit (``mesh._cotangents``).
  The package-wide private modules in :data:`SHARED_PRIVATE` are the exception: they are the
  package's shared private I/O and checks, importable from anywhere.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "sns_np"
PACKAGE = "sns_np"

#: top-level private modules every unit may import (shared private I/O, checks, progress)
SHARED_PRIVATE = {"sns_np._atomic", "sns_np._npz", "sns_np._validation", "sns_np._progress",
                  "sns_np._signals", "sns_np._version"}

#: (importer, imported) units that must never depend on each other in that direction;
#: ``"*"`` is any unit
FORBIDDEN = [
    ("geometry", "nn"),       # geometry works on the surface-map protocol only
    ("geometry", "surface"),
    ("mesh", "surface"),      # mesh sits below the neural surface and everything built on it
    ("mesh", "spectral"),
    ("mesh", "flows"),
    ("surface", "flows"),     # flows are built on surfaces, never the other way
    ("*", "cli"),             # the command line sits on top
]

#: units that only the listed units may import (batch sits on top, under the command line)
ONLY_FROM = {"batch": {"cli"}}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def is_package(mod: str) -> bool:
    return MODULES.get(mod, Path()).name == "__init__.py"


def unit(mod: str) -> str:
    """``sns_np.geometry.chart`` -> ``geometry``; ``sns_np.sampling`` -> ``sampling``."""
    parts = mod.split(".")
    return parts[1] if len(parts) > 1 else ""


def resolve(importer: str, module: str | None, level: int) -> str:
    if level == 0:
        return module or ""
    base = importer.split(".")
    if not is_package(importer):
        base = base[:-1]
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def imports(mod: str):
    """``(line, target module, imported name or None, local alias of a module or None)``."""
    tree = ast.parse(MODULES[mod].read_text(encoding="utf-8"), str(MODULES[mod]))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith(PACKAGE):
                    yield node.lineno, a.name, None, a.asname
        elif isinstance(node, ast.ImportFrom):
            target = resolve(mod, node.module, node.level)
            if not target.startswith(PACKAGE):
                continue
            for a in node.names:
                sub = f"{target}.{a.name}"
                if sub in MODULES:           # ``from pkg import module``
                    yield node.lineno, sub, None, a.asname or a.name
                else:
                    yield node.lineno, target, a.name, None


def private_attributes(mod: str, aliases: dict):
    """``(line, alias, attribute)`` for ``alias._attr`` where alias names an imported module."""
    tree = ast.parse(MODULES[mod].read_text(encoding="utf-8"), str(MODULES[mod]))
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases and node.attr.startswith("_")
                and not node.attr.startswith("__")):
            yield node.lineno, aliases[node.value.id], node.attr


def edges():
    """{(importer unit, imported unit): [where]} over all modules, the root package excluded."""
    out = {}
    for mod in MODULES:
        if mod == PACKAGE or mod == f"{PACKAGE}.__main__":
            continue
        for line, target, _, _ in imports(mod):
            a, b = unit(mod), unit(target)
            if a != b and b and target not in SHARED_PRIVATE:
                out.setdefault((a, b), []).append(f"{MODULES[mod].relative_to(ROOT.parent)}:{line}")
    return out


def cycles(graph):
    """The strongly connected components with more than one unit (Tarjan)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_walk_sees_the_package():
    assert {"geometry", "mesh", "nn", "surface", "flows", "spectral", "sampling", "cli"} <= {
        unit(m) for m in MODULES}
    e = edges()
    assert ("flows", "surface") in e and ("sampling", "geometry") in e     # known real edges
    # a deferred import inside a function counts (surface.model imports mesh in to_mesh)
    assert ("surface", "mesh") in e


def test_no_cycle_between_subpackages():
    graph = {}
    e = edges()
    for a, b in e:
        graph.setdefault(a, set()).add(b)
    found = cycles(graph)
    detail = []
    for comp in found:
        for (a, b), where in sorted(e.items()):
            if a in comp and b in comp:
                detail.append(f"  {a} -> {b}: {', '.join(where[:3])}")
    assert found == [], f"import cycles between units {found}:\n" + "\n".join(detail)


@pytest.mark.parametrize("importer, imported", FORBIDDEN)
def test_forbidden_direction(importer, imported):
    bad = {k: v for k, v in edges().items()
           if k[1] == imported and (importer == "*" or k[0] == importer)}
    assert bad == {}, f"{importer} must not import {imported}: {bad}"


@pytest.mark.parametrize("imported", sorted(ONLY_FROM))
def test_only_the_top_imports_the_top(imported):
    bad = {k: v for k, v in edges().items() if k[1] == imported and k[0] not in ONLY_FROM[imported]}
    assert bad == {}, f"only {sorted(ONLY_FROM[imported])} may import {imported}: {bad}"


def test_no_private_name_crosses_a_subpackage():
    bad = []
    for mod in MODULES:
        aliases = {}
        for line, target, name, alias in imports(mod):
            where = f"{MODULES[mod].relative_to(ROOT.parent)}:{line}"
            if unit(target) == unit(mod) or target in SHARED_PRIVATE:
                continue
            private_module = any(part.startswith("_") and not part.startswith("__")
                                 for part in target.split("."))
            if private_module:
                bad.append(f"{where}: private module {target}")
            elif name is not None and name.startswith("_"):
                bad.append(f"{where}: private name {target}.{name}")
            if alias is not None and name is None:
                aliases[alias] = target
        for line, target, attr in private_attributes(mod, aliases):
            bad.append(f"{MODULES[mod].relative_to(ROOT.parent)}:{line}: private attribute "
                       f"{target}.{attr}")
    bad = sorted(set(bad))
    assert bad == [], "private names imported across subpackages:\n" + "\n".join(bad)


def test_shared_private_modules_exist_and_import_no_unit():
    """The shared private modules are leaves: they import only each other (and errors)."""
    for mod in SHARED_PRIVATE:
        assert mod in MODULES, mod
        for _, target, _, _ in imports(mod):
            assert target in SHARED_PRIVATE or unit(target) in ("errors", ""), (mod, target)
