"""Every Python example of the README and of the manual (docs/*.md) runs as written.

A page's ```python blocks run in order in one namespace, as a reader would paste them into one
session (a later block may use a name an earlier one defined), in an empty working directory
that sees the clone's `tests/` and `python/` folders.
Blocks that cannot run here (a Slurm cluster) are fenced ```py instead, and the page says why.
A block after a line `<!-- example: slow -->` (a study of minutes of CPU) runs with --runslow
only, in the page's `[slow]` test, which runs every block of the page.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
PAGES = [README, *sorted((REPO / "docs").glob("*.md"))]
FENCE = re.compile(r"^(<!-- example: slow -->\n)?```python\n(.*?)^```",
                   flags=re.DOTALL | re.MULTILINE)


def _examples(page: Path) -> list[tuple[bool, str]]:
    """(slow, code) of each ```python block of ``page``, in order."""
    return [(bool(slow), code) for slow, code in FENCE.findall(page.read_text(encoding="utf-8"))]


def _blocks(page: Path) -> list[str]:
    return [code for _, code in _examples(page)]


CASES = [pytest.param(p, False, id=str(p.relative_to(REPO))) for p in PAGES if _blocks(p)]
CASES += [pytest.param(p, True, id=f"{p.relative_to(REPO)}[slow]", marks=pytest.mark.slow)
          for p in PAGES if any(slow for slow, _ in _examples(p))]


@pytest.mark.parametrize(("page", "with_slow"), CASES)
def test_page_examples_run(page: Path, with_slow: bool, tmp_path: Path,
                           monkeypatch: pytest.MonkeyPatch) -> None:
    import matplotlib

    matplotlib.use("Agg")  # figures in examples are written to files, never shown
    for folder in ("tests", "python"):  # as in a clone: examples may read the shipped data
        (tmp_path / folder).symlink_to(REPO / folder, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for i, (slow, code) in enumerate(_examples(page)):
        if slow and not with_slow:
            continue
        try:
            exec(compile(code, f"{page.name}[block {i}]", "exec"), namespace)  # noqa: S102
        except Exception as exc:  # the page and the block, not only the line, in the report
            raise AssertionError(f"{page.relative_to(REPO)}, python block {i}: {exc!r}") from exc


def test_every_example_page_is_collected() -> None:
    """The harness sees the examples: the README's and the manual's pages that have some."""
    with_examples = {p.name for p in PAGES if _blocks(p)}
    assert {"README.md", "usage.md", "schema.md", "io.md", "ensembles.md"} <= with_examples


def test_schema_page_yaml_example_is_a_valid_model() -> None:
    import yaml

    import oxyline

    text = (REPO / "docs" / "schema.md").read_text(encoding="utf-8")
    block = re.search(r"```yaml\n(name: carotid.*?)```", text, flags=re.DOTALL)
    assert block is not None
    model = oxyline.load_model(yaml.safe_load(block.group(1)))
    res = oxyline.simulate(model, cycles=2)
    assert res.vessels == ["CCA", "ICA", "ECA"]


def test_schema_page_shows_the_shipped_example() -> None:
    """The schema page's first model file is python/oxyline/examples/bifurcation.yaml as shipped."""
    from ruamel.yaml import YAML

    import oxyline

    blocks = re.findall(r"```yaml\n(.*?)```", (REPO / "docs" / "schema.md").read_text(),
                        flags=re.DOTALL)
    shipped = Path(oxyline.__file__).parent / "examples" / "bifurcation.yaml"
    yaml = YAML(typ="safe", pure=True)
    assert yaml.load(blocks[0]) == yaml.load(shipped.read_text())


def test_docs_examples_need_nothing_outside_the_repository() -> None:
    """Python blocks of the pages read only files of the repository (no ../shared)."""
    for page in PAGES:
        for code in _blocks(page):
            assert "../shared" not in code and "shared/" not in code, page.name
            for rel in re.findall(r"\"((?:tests|python)/[^\"]+/)\"", code):
                assert (REPO / rel).is_dir(), (page.name, rel)


def test_readme_is_a_door() -> None:
    """The README stays short and speaks of the product, not of work items."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    assert "doi:10.1038/s41598-018-23743-2" in text
    for page in PAGES:
        words = page.read_text(encoding="utf-8")
        assert not re.search(r"\bissue \d+|\bsession \d+", words, flags=re.IGNORECASE), page.name
