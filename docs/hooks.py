"""mkdocs hook: the home page is the README.

``docs/index.md`` holds the line ``{README}``; it is replaced by README.md, and the
README's links to repository files that are not pages of this site
(``benchmarks/RESULTS.md``, ...) become plain text naming the file, so
``mkdocs build --strict`` does not report them as missing pages.
"""

import pathlib
import re

_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")
_PLACEHOLDER = "{README}"


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri != "index.md" or _PLACEHOLDER not in markdown:
        return markdown
    docs = pathlib.Path(config["docs_dir"])
    readme = (docs.parent / "README.md").read_text(encoding="utf-8")

    def fix(match):
        text, target = match.groups()
        path = target.split("#")[0]
        if "://" in target or not path or (docs / path).exists():
            return match.group(0)
        return text if text.strip("`") == target else f"{text} (`{target}`)"

    return markdown.replace(_PLACEHOLDER, _LINK.sub(fix, readme))
