"""Hostile and odd model files: every one gives a typed error naming the file,
quickly and in bounded memory, never a hang, a raw decoding error or a silently wrong model."""

from __future__ import annotations

import json
import resource
import sys
import warnings
from pathlib import Path

import pytest
from conftest import data_path, run_child

import oxyline
from oxyline.io import read_model, save_model
from oxyline.io.native import read_mapping

EXAMPLE = Path(oxyline.__file__).parent / "examples" / "bifurcation.yaml"


def _bomb(levels: int = 9) -> str:
    """A "billion laughs" YAML file under ``description:``: 9 aliases of 9 aliases ... expand to
    9**levels strings from ~1.3 KB of text."""
    anchors = ["  l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for i in range(1, levels + 1):
        anchors.append(f"  l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]")
    return "description:\n" + "\n".join(anchors) + "\n"


def _capped() -> None:
    """Child-process setup: SIGINT default (conftest) and at most 2 GiB of address space, so
    that a regression fails the test instead of taking the machine's memory."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))


def test_alias_bomb_is_refused_quickly_in_bounded_memory(tmp_path: Path) -> None:
    text = EXAMPLE.read_text().replace("name: bifurcation\n", "name: bifurcation\n" + _bomb())
    assert len(_bomb()) < 1500
    p = tmp_path / "bomb.yaml"
    p.write_text(text)
    code = ("import sys, oxyline\n"
            "try:\n    oxyline.load_model(sys.argv[1])\n"
            "except oxyline.ModelError as e:\n    print('ModelError:', e)\n")
    # before the fix this child ran > 60 s and grew without bound; now it answers at once
    done = run_child([sys.executable, "-c", code, str(p)], timeout=60, preexec_fn=_capped)
    assert done.returncode == 0, done.stderr
    assert "ModelError:" in done.stdout and str(p) in done.stdout
    assert "alias" in done.stdout


def test_recursive_alias_is_a_model_error(tmp_path: Path) -> None:
    p = tmp_path / "loop.yaml"
    p.write_text(EXAMPLE.read_text().replace("name: bifurcation\n",
                                             "name: bifurcation\ndescription: &d [a, *d]\n"))
    with pytest.raises(oxyline.ModelError, match="recursive"):
        oxyline.load_model(p)


@pytest.mark.parametrize("kind", ["latin-1", "binary", "utf-16-without-bom"])
def test_undecodable_files_are_model_errors_naming_the_file(tmp_path: Path, kind: str) -> None:
    text = EXAMPLE.read_text().replace("name: parent", "name: pärent")
    raw = {"latin-1": text.encode("latin-1"), "binary": bytes(range(256)) * 4,
           "utf-16-without-bom": text.encode("utf-16-le")}[kind]
    for suffix in (".yaml", ".json"):
        p = tmp_path / f"model{suffix}"
        p.write_bytes(raw)
        with pytest.raises(oxyline.ModelError, match=str(p).replace("\\", "\\\\")) as info:
            oxyline.load_model(p)
        assert "UTF-8" in str(info.value) or "binary" in str(info.value)
        with pytest.raises(oxyline.ModelError):
            read_model(p)


def test_utf16_and_utf8_bom_files_are_read(tmp_path: Path) -> None:
    """YAML allows UTF-16/32 with a byte-order mark; editors on Windows write them."""
    text = EXAMPLE.read_text().replace("name: parent", "name: pärent")
    for codec in ("utf-16", "utf-8-sig"):
        p = tmp_path / f"{codec}.yaml"
        p.write_bytes(text.encode(codec))
        assert oxyline.load_model(p).vessel_names[0] == "pärent"


def test_duplicate_keys_are_errors_naming_the_key(tmp_path: Path) -> None:
    p = tmp_path / "dup.yaml"
    p.write_text(EXAMPLE.read_text().replace("arrangement: inverted-L\n",
                                             "arrangement: inverted-L\nperiod: 2.0\n"))
    with pytest.raises(oxyline.ModelError, match=r"dup\.yaml.*line 10.*duplicate key \"period\""):
        oxyline.load_model(p)
    j = tmp_path / "dup.json"
    data = json.dumps(oxyline.load_model(EXAMPLE).to_dict())
    j.write_text(data.replace('"name": "parent"', '"name": "parent", "length": 1.0', 1))
    with pytest.raises(oxyline.ModelError, match=r"dup\.json.*duplicate key 'length'"):
        oxyline.load_model(j)
    # keys starting with "_" are comments; svZeroDSolver's own files repeat "_comment_"
    j.write_text('{"_comment_": "a", "_comment_": "b", "x": 1}')
    assert read_mapping(j) == {"_comment_": "b", "x": 1}


def test_null_names_are_errors_not_the_string_none(tmp_path: Path) -> None:
    p = tmp_path / "null.yaml"
    p.write_text(EXAMPLE.read_text().replace("name: parent", "name: null"))
    with pytest.raises(oxyline.ModelError, match="vessel #0: 'name' must be a name, got None"):
        oxyline.load_model(p)
    p.write_text(EXAMPLE.read_text().replace("name: bifurcation", "name: ~"))
    with pytest.raises(oxyline.ModelError, match="model: 'name' must be a name"):
        oxyline.load_model(p)


def test_yaml_12_numbers_and_words(tmp_path: Path) -> None:
    """YAML 1.2: ``5.0e5`` is a number (a string in YAML 1.1), ``yes`` is a word; what
    save_model writes reads back as the same model, also for names that look like numbers."""
    m = oxyline.load_model(EXAMPLE)
    assert m.to_dict()["vessels"][0]["youngs_modulus"] == 5.0e5
    # shipped models too (read with libyaml plus YAML 1.2's number rule)
    bcs = oxyline.load_model("bifurcation").to_dict()["boundary_conditions"]
    assert bcs["ica_out"]["resistance"] == 2.8931e9
    src = m.to_dict()
    src["vessels"][0]["name"] = "1e5"
    src["vessels"][1]["name"] = "yes"
    p = save_model(src, tmp_path / "round.yaml")
    back = oxyline.load_model(p)
    assert back.vessel_names == ["1e5", "yes", "daughter2"]
    assert back.canonical == oxyline.load_model(src).canonical


@pytest.mark.parametrize("source", [None, 42, 3.5, [1, 2], b"bifurcation"])
def test_load_model_of_a_non_source_is_a_clear_error(source: object) -> None:
    with pytest.raises(oxyline.ModelError, match="load_model: expected a model dict, a file path"):
        oxyline.load_model(source)  # type: ignore[arg-type]


@pytest.mark.parametrize("text", ["", "- a\n- b\n", "just words\n", "null\n"])
def test_top_level_must_be_a_mapping(tmp_path: Path, text: str) -> None:
    p = tmp_path / "m.yaml"
    p.write_text(text)
    with pytest.raises(oxyline.ModelError, match="top level must be a mapping"):
        oxyline.load_model(p)


def test_python_tags_and_deep_nesting_are_model_errors(tmp_path: Path) -> None:
    p = tmp_path / "tag.yaml"
    p.write_text("name: !!python/object/apply:os.system ['echo hi']\n")
    with pytest.raises(oxyline.ModelError, match="tag.yaml: cannot parse YAML"):
        oxyline.load_model(p)
    j = tmp_path / "deep.json"
    j.write_text('{"a": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(oxyline.ModelError, match="deep.json"):
        oxyline.load_model(j)


def test_file_size_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from oxyline.io import native

    monkeypatch.setattr(native, "MAX_YAML_BYTES", 100)
    with pytest.raises(oxyline.ModelError, match="MAX_YAML_BYTES"):
        oxyline.load_model(EXAMPLE)


def test_openbf_importer_warns_when_blood_is_missing(tmp_path: Path) -> None:
    pytest.importorskip("oxyline.io.openbf")
    from oxyline.io.openbf import OpenBFWarning, read_openbf

    src = data_path("openbf", "models/boileau2015/ibif")
    text = (src / "ibif.yaml").read_text()
    head, rest = text.split("blood:\n", 1)
    rest = rest.split("solver:", 1)[1]
    (tmp_path / "ibif.yaml").write_text(head + "solver:" + rest)
    (tmp_path / "ibif_inlet.dat").write_bytes((src / "ibif_inlet.dat").read_bytes())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_openbf(tmp_path / "ibif.yaml")
    msgs = [str(w.message) for w in caught if issubclass(w.category, OpenBFWarning)]
    assert any("no 'blood:' section" in m and "1060" in m for m in msgs), msgs
    with warnings.catch_warnings(record=True) as caught:  # the shipped file has blood: no warning
        warnings.simplefilter("always")
        read_openbf(src / "ibif.yaml")
    assert not any("blood" in str(w.message) for w in caught)
