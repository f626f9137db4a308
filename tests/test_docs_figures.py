"""Every picture under docs/ is shown in a document with a caption (an italic paragraph right
after it), so nobody has to guess what a picture shows or how it was made."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMAGE = re.compile(r"!\[[^\]]*\]\(([^)]+)\)")


def test_every_image_under_docs_has_a_caption() -> None:
    docs = ROOT / "docs"
    captioned: set[Path] = set()
    for md in [ROOT / "README.md", *docs.rglob("*.md")]:
        text = md.read_text(encoding="utf-8")
        for match in IMAGE.finditer(text):
            after = text[match.end() :].lstrip("\n")
            rest = after.split("\n\n", 1)[0]
            if rest.startswith("*") and rest.rstrip().endswith("*") and len(rest) > 40:
                captioned.add((md.parent / match.group(1)).resolve())
    images = {p.resolve() for p in docs.rglob("*") if p.suffix.lower() in (".png", ".gif", ".jpg")}
    missing = sorted(str(p.relative_to(ROOT)) for p in images - captioned)
    assert not missing, f"images without a caption: {missing}"


def test_the_readme_is_a_short_manual() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 300
    for heading in ("## Install and run, test", "## Tutorial", "## Where to read more"):
        assert heading in text, heading
