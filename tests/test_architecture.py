"""The package's shape: stages import downward only, no import cycles, every public name documented."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _import_graph():
    grimp = pytest.importorskip("grimp", reason="pip install import-linter (in lipgen[test])")
    return grimp.build_graph("lipgen", cache_dir=None)


def test_stages_import_only_the_stages_below_them():
    import logging

    cli = pytest.importorskip("importlinter.cli", reason="pip install import-linter (in lipgen[test])")
    # lint_imports configures logging with disable_existing_loggers: keep the other tests' loggers on
    loggers = [lg for lg in logging.root.manager.loggerDict.values() if isinstance(lg, logging.Logger)]
    disabled = {lg: lg.disabled for lg in loggers}
    try:
        status = cli.lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True, no_logo=True)
    finally:
        for lg, was in disabled.items():
            lg.disabled = was
    assert status == 0


def test_no_import_cycles():
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    g = _import_graph()
    mods = sorted(g.modules)
    ix = {m: i for i, m in enumerate(mods)}
    edges = np.array([(ix[m], ix[d]) for m in mods for d in g.find_modules_directly_imported_by(m)])
    A = csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(len(mods), len(mods)))
    n, label = connected_components(A, directed=True, connection="strong")
    cycles = [[mods[i] for i in np.flatnonzero(label == k)] for k in range(n) if (label == k).sum() > 1]
    assert cycles == []


def _public_objects():
    griffe = pytest.importorskip("griffe", reason="pip install 'mkdocstrings[python]' (in lipgen[test])")
    pkg = griffe.load("lipgen", search_paths=[str(ROOT)], docstring_parser="numpy", resolve_aliases=False)

    def walk(mod):
        for name in mod.exports or []:
            name = name if isinstance(name, str) else name.name
            obj = mod.members.get(name)
            if obj is None or obj.is_alias:
                continue  # re-exported: checked where it is defined
            yield obj
            if obj.is_class:
                yield from (m for n, m in obj.members.items()
                            if not n.startswith("_") and not m.is_alias and (m.is_function or m.is_class))
        for sub in mod.modules.values():
            yield from walk(sub)

    return list(walk(pkg))


def test_every_public_name_has_a_docstring():
    objs = _public_objects()
    assert len(objs) > 300
    missing = [f"{o.path} ({o.kind.value})" for o in objs if not o.docstring]
    assert missing == []
