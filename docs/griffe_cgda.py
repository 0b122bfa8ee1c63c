"""Griffe extension for the API pages: read the project's docstring conventions.

- ``Example:`` (singular) sections become ``Examples:``, so doctests render as code
  (Griffe's Google parser treats ``Example:`` as a plain admonition).
- An ``Args:`` entry that names several parameters over more than one line
  (``a, b, c,`` then ``d: as in run_ie``) is joined onto one line, so it parses as
  one entry naming them all.
"""

import re

import griffe

_EXAMPLE = re.compile(r"^(\s*)Example:\s*$", re.MULTILINE)
# "    a, b, c,\n        d, e: text" -> "    a, b, c, d, e: text"
_CONTINUED_NAMES = re.compile(r"^(\s+[\w, ]+,)\n\s+(?=[\w, ]+:)", re.MULTILINE)


class CgdaDocstrings(griffe.Extension):
    def on_instance(self, *, obj, **kwargs):
        doc = obj.docstring
        if doc is None:
            return
        value = _EXAMPLE.sub(r"\1Examples:", doc.value)
        value = _CONTINUED_NAMES.sub(r"\1 ", value)
        doc.value = value
