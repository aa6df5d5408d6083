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
