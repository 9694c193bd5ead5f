"""A griffe extension for the API pages: the library's docstrings, read as the site shows them.

The docstrings follow the house style (``Example:``, Sphinx roles such as ``:class:`Foo```),
which Python's ``help()`` and the doctests read as they are. Griffe's Google parser treats
only ``Examples:`` as an example section (rendering the doctest as code) and leaves roles as
text, so before parsing this extension renames the heading and turns a role into plain code.
Only the site's copy of a docstring changes; the source does not.
"""

from __future__ import annotations

import re
from typing import Any

from griffe import Extension, Object

_EXAMPLE = re.compile(r"^(\s*)Example:\s*$", re.MULTILINE)
_ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|exc|obj):`~?([^`]+)`")


class HouseDocstrings(Extension):
    """``Example:`` read as an examples section, ``:role:`name``` as ``name`` in code."""

    def on_object(self, *, obj: Object, **kwargs: Any) -> None:
        if obj.docstring is None:
            return
        text = _EXAMPLE.sub(r"\1Examples:", obj.docstring.value)
        obj.docstring.value = _ROLE.sub(r"``\1``", text)
