"""Strings from data in report.md, and report.md as HTML: the one place both are made safe.

Writers: every string that comes from data (a scenario file's name and effects, a file
name, an error message, a value read from a file) goes into report.md through
``md_text``, which escapes it once for Markdown and for HTML: it reads as the same
characters in any Markdown viewer and can never become a heading, a list, a table cell
break, emphasis, raw HTML, a link or an image (a scenario named
``![x](http://example.com/a.png)`` shows as those characters, nothing is fetched).

Reader: ``markdown_html`` renders report.md for ``flexcal report`` (python-markdown,
tables and fenced code) so that the page addresses nothing: raw HTML is shown as text,
every link keeps its text and loses its address (so a link a writer forgot to escape
points nowhere), and an image is kept only when it names one of the folder's own PNGs,
which it then holds as a ``data:image/png;base64`` address; any other image shows its
alt text.
"""

from __future__ import annotations

import html
import re
from typing import Mapping

__all__ = ["md_text", "markdown_html"]

# the characters python-markdown reads as syntax anywhere in a line and lets a backslash
# escape (``Markdown.ESCAPED_CHARS`` with the tables extension, '>' aside: it becomes &gt;)
_INLINE_SYNTAX = re.compile(r"([\\`*_{}\[\]()!|])")
# syntax only at the start of a line (heading, list item, numbered item): escaped there
_BLOCK_START = re.compile(r"^(\d*)([#+\-.])")
# control characters (python-markdown's own placeholders STX/ETX among them), whitespace aside
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0e-\x1f\x7f]")


def md_text(value: object) -> str:
    """``value`` as text for report.md: one line (whitespace runs become one space, control
    characters are dropped), ``& < >`` as HTML entities, Markdown syntax characters
    backslash-escaped."""
    text = html.escape(" ".join(_CONTROL.sub("", str(value)).split()), quote=False)
    return _BLOCK_START.sub(r"\1\\\2", _INLINE_SYNTAX.sub(r"\\\1", text))


def markdown_html(text: str, pictures: Mapping[str, str]) -> tuple[str, set[str]]:
    """(HTML of the Markdown ``text``, names of the pictures it placed).

    pictures: file name -> base64 of a PNG of the run folder; ``![caption](name.png)``
    with such a name becomes ``<img src="data:image/png;base64,...">``. Raw HTML is shown
    as text, links lose their address, other images become their alt text, and no element
    keeps an ``href``, ``src`` or ``style`` attribute otherwise (module docstring)."""
    import markdown
    from markdown.treeprocessors import Treeprocessor

    placed: set[str] = set()

    class NoAddresses(Treeprocessor):
        def run(self, root):
            for element in root.iter():
                if element.tag == "img" and element.get("src") in pictures:
                    name, alt = element.get("src"), element.get("alt", "")
                    element.attrib.clear()
                    element.set("src", f"data:image/png;base64,{pictures[name]}")
                    element.set("alt", alt)
                    placed.add(name)
                    continue
                if element.tag == "img":  # not a picture of the folder: its alt text instead
                    element.text = element.get("alt", "")
                if element.tag in ("a", "img"):
                    element.tag = "span"
                    element.attrib.clear()
                for attribute in ("href", "src", "style"):
                    element.attrib.pop(attribute, None)

    md = markdown.Markdown(extensions=["tables", "fenced_code"])
    md.preprocessors.deregister("html_block")  # the documented way to escape raw HTML (Python-Markdown 3)
    md.inlinePatterns.deregister("html")
    md.treeprocessors.register(NoAddresses(md), "flexcal_no_addresses", -10)  # after "unescape" (0)
    return md.convert(text), placed
