"""Every ```python block of the README runs as written (the documented examples stay true)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.DOTALL)


@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_readme_example_runs(code: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    exec(compile(code, str(README), "exec"), {"__name__": "__readme__"})  # noqa: S102 - documented examples


def test_readme_yaml_example_is_a_valid_model(tmp_path: Path) -> None:
    import yaml

    import oxyline

    text = README.read_text()
    block = re.search(r"```yaml\n(name: carotid.*?)```", text, flags=re.DOTALL)
    assert block is not None
    model = oxyline.load_model(yaml.safe_load(block.group(1)))
    res = oxyline.simulate(model, cycles=2)
    assert res.vessels == ["CCA", "ICA", "ECA"]


def test_readme_shows_the_shipped_example() -> None:
    """The README's first model file is python/oxyline/examples/bifurcation.yaml as shipped."""
    from ruamel.yaml import YAML

    import oxyline

    blocks = re.findall(r"```yaml\n(.*?)```", README.read_text(), flags=re.DOTALL)
    shipped = Path(oxyline.__file__).parent / "examples" / "bifurcation.yaml"
    yaml = YAML(typ="safe", pure=True)
    assert yaml.load(blocks[0]) == yaml.load(shipped.read_text())


def test_docs_examples_need_nothing_outside_the_repository() -> None:
    """Python blocks of docs/*.md read only files of the repository (no ../shared)."""
    repo = README.parent
    for doc in sorted((repo / "docs").glob("*.md")):
        for code in re.findall(r"```python\n(.*?)```", doc.read_text(), flags=re.DOTALL):
            assert "../shared" not in code and "shared/" not in code, doc.name
            for rel in re.findall(r"\"((?:tests|python)/[^\"]+/)\"", code):
                assert (repo / rel).is_dir(), (doc.name, rel)
