"""Griffe extension: lipgen's docstrings use Sphinx roles (``:func:`x```), which Markdown does
not know. They become cross-references of the site (optional: a name the reference does not
document stays plain code instead of a broken link)."""

from __future__ import annotations

import re

import griffe

ROLE = re.compile(r":(?:mod|class|func|meth|data|attr|obj|exc):`(~?)([^`<]+?)`")


def _ref(match: re.Match) -> str:
    short, target = match.group(1), match.group(2).strip().rstrip("()")
    shown = target.rsplit(".", 1)[-1] if short else target
    if not target.startswith("lipgen"):
        return f"`{shown}`"
    return f'<autoref optional identifier="{target}"><code>{shown}</code></autoref>'


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring as it is loaded."""

    def on_object(self, *, obj, **kwargs) -> None:
        if obj.docstring is not None and ":" in obj.docstring.value:
            obj.docstring.value = ROLE.sub(_ref, obj.docstring.value)
