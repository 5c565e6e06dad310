"""The docstrings of the public API: every example runs, and every public definition has one.

* ``test_doctest`` runs the ``Examples`` of every docstring of the package (each docstring
  is one test case), so that ``python -m pytest -q tests``, the README's test command and
  CI's, checks them. Examples use tiny networks and budgets: the whole set takes about 40 s
  (``tox -e nojit`` leaves them out: without the JIT their small fits take minutes).
* ``test_every_public_definition_has_an_example`` lists the public definitions (the names in
  each public module's ``__all__`` and the public methods of those classes) whose numpydoc
  docstring has no ``Examples`` section, and fails if there is any.

What counts as public: functions and classes named in ``__all__``, and the methods defined
in those classes' own bodies (plain, class and static methods) whose names do not start with
an underscore. Not counted: properties and constants (attributes, shown in their class's
example), and exception and warning classes (raised, never called: their docstring says when).
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import sns_np

#: the public modules (a subpackage's __all__ re-exports its modules' public names)
PUBLIC_MODULES = ["nn", "geometry", "shapes", "mesh", "sampling", "fields", "spectral", "flows",
                  "surface", "testing", "protocol", "errors", "quadrature", "demo", "batch"]

#: public definitions allowed to lack an Examples section (none)
PENDING = set()

#: optional dependencies an example may need; without them that example is skipped
OPTIONAL = ("meshio", "trimesh", "igl", "matplotlib", "distributed", "threadpoolctl")

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def public_definitions():
    """{qualified name: object} of the public functions, classes and methods."""
    found = {}
    for modname in PUBLIC_MODULES:
        module = importlib.import_module(f"sns_np.{modname}")
        for name in getattr(module, "__all__", []):
            obj = getattr(module, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue
            if inspect.isclass(obj) and issubclass(obj, (BaseException,)):
                continue
            key = f"{obj.__module__}.{obj.__qualname__}"
            found.setdefault(key, obj)
            if inspect.isclass(obj):
                for attr, value in vars(obj).items():
                    if attr.startswith("_"):
                        continue
                    if isinstance(value, (staticmethod, classmethod)):
                        value = value.__func__
                    if inspect.isfunction(value):
                        found.setdefault(f"{key}.{attr}", value)
    return found


def _has_examples(obj):
    doc = inspect.getdoc(obj) or ""
    lines = doc.splitlines()
    return any(line.strip() == "Examples" and i + 1 < len(lines)
               and set(lines[i + 1].strip()) == {"-"} and ">>>" in doc
               for i, line in enumerate(lines))


def test_every_public_definition_has_an_example():
    defs = public_definitions()
    assert len(defs) > 150                                  # the walk found the API
    missing = sorted(k for k, obj in defs.items() if k not in PENDING and not _has_examples(obj))
    assert missing == [], f"{len(missing)} public definitions without an Examples section:\n" \
        + "\n".join(missing)
    done = sorted(k for k in PENDING if k in defs and _has_examples(defs[k]))
    assert done == [], f"remove from PENDING, they have examples now: {done}"
    unknown = sorted(PENDING - set(defs))
    assert unknown == [], f"PENDING names that are not public definitions: {unknown}"


def _doctests():
    finder = doctest.DocTestFinder(exclude_empty=True)
    tests = []
    for info in pkgutil.walk_packages(sns_np.__path__, "sns_np."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for test in finder.find(module, info.name):
            if test.examples:
                tests.append(test)
    return sorted(tests, key=lambda t: t.name)


DOCTESTS = _doctests()


def test_the_doctests_were_found():
    assert len(DOCTESTS) > 150


@pytest.mark.slow_nojit           # tiny fits: seconds with the JIT, minutes without
@pytest.mark.parametrize("test", DOCTESTS, ids=[t.name for t in DOCTESTS])
def test_doctest(test, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                             # examples that write files
    old = np.get_printoptions()
    try:
        runner = doctest.DocTestRunner(optionflags=FLAGS)
        out = []
        runner.run(test, out=out.append, clear_globs=True)
    finally:
        np.set_printoptions(**old)
    report = "".join(out)
    if runner.failures:
        for dep in OPTIONAL:
            if f"No module named '{dep}'" in report:
                pytest.skip(f"needs the optional dependency {dep}")
        pytest.fail(report, pytrace=False)
