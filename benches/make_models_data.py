"""Regenerate ``python/oxyline/models_data/*.yaml`` from the openBF model library in
``../shared/networks/openbf`` (Apache-2.0) with :func:`oxyline.io.openbf.to_native_dict`, and
``whole-body-140`` from circulatory_autogen's FinalModel in ``../shared/networks/circulatory_autogen``
(Apache-2.0) with :func:`oxyline.io.circulatory_autogen.to_native_dict` (inflow: the Mynard
template of ``../shared/networks/pwdb``, MIT).

    python benches/make_models_data.py
"""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import yaml

from oxyline.io import circulatory_autogen
from oxyline.io.openbf import to_native_dict

REPO = Path(__file__).resolve().parents[1]
OPENBF = REPO.parent / "shared" / "networks" / "openbf"
OUT = REPO / "python" / "oxyline" / "models_data"
CA = REPO.parent / "shared" / "networks" / "circulatory_autogen"
PWDB = REPO.parent / "shared" / "networks" / "pwdb"

SOURCES = {
    "cca": ("models/boileau2015/cca/cca.yaml", "Boileau et al. 2015, common carotid artery"),
    "aortic-bifurcation": ("models/boileau2015/ibif/ibif.yaml",
                           "Boileau et al. 2015, aortic bifurcation"),
    "adan56": ("models/boileau2015/adan56/adan56.yaml",
               "Boileau et al. 2015, ADAN56 (Blanco et al. 2015); inflow repaired"),
    "circle-of-willis": ("models/alastruey2007/circle_of_willis.yaml",
                         "Alastruey et al. 2007, circle of Willis + main systemic arteries"),
    "matthys37": ("models/matthys2007/invitro_model.yaml",
                  "Matthys et al. 2007, 37-artery in-vitro network"),
}


def _flow(value: object) -> str:
    return yaml.safe_dump(value, default_flow_style=True, width=10**6, sort_keys=False).strip()


def dump(d: dict) -> str:
    """Native YAML: block mappings at the top, one flow mapping per vessel and per boundary
    condition (tables on one line)."""
    lines = []
    for key, value in d.items():
        if key == "vessels":
            lines.append("vessels:")
            lines += [f"  - {_flow(v)}" for v in value]
        elif key == "boundary_conditions":
            lines.append("boundary_conditions:")
            lines += [f"  {node}: {_flow(bc)}" for node, bc in value.items()]
        elif isinstance(value, dict):
            lines.append(f"{key}: {_flow(value)}")
        else:
            lines.append(yaml.safe_dump({key: value}, sort_keys=False, width=100,
                                        default_flow_style=False).rstrip())
    return "\n".join(lines) + "\n"


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for name, (rel, cite) in SOURCES.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            d = to_native_dict(OPENBF / rel, name=name)
        notes = sorted({str(w.message) for w in caught})
        header = [f"# oxyline built-in model '{name}': {cite}.",
                  f"# Converted from the openBF model library (INSIGNEO/openBF, Apache-2.0), file {rel},",
                  "# by oxyline.io.openbf.to_native_dict (defaults: linear taper, WK2 = R1 parallel to Cc,",
                  "# linearised at the steady mean pressure); regenerate: benches/make_models_data.py.",
                  "# Citations: NOTICE.",
                  *[f"# importer note: {n}" for n in notes]]
        text = "\n".join(header) + "\n" + dump(d)
        if yaml.safe_load(text) != d:
            raise SystemExit(f"{name}: YAML round trip changed the model")
        (OUT / f"{name}.yaml").write_text(text)
        print(name, len(d["vessels"]), "vessels")
    shutil.copy(OPENBF / "LICENSE", OUT / "LICENSE")
    whole_body()


def whole_body() -> None:
    """``whole-body-140``: circulatory_autogen FinalModel arterial tree (commit 8e028f37)."""
    res = CA / "resources"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = circulatory_autogen.to_native_dict(
            res / "FinalModel_vessel_array.csv", res / "FinalModel_parameters.csv",
            obs_data_json=res / "FinalModel_obs_data.json",
            mynard_template=PWDB / "Mynard2015_aortic_flow_template.csv", name="whole-body-140")
    notes = sorted({str(w.message) for w in caught})
    header = ["# oxyline built-in model 'whole-body-140': circulatory_autogen FinalModel arterial tree.",
              "# Converted from FinbarArgus/circulatory_autogen (Apache-2.0, commit 8e028f37),",
              "# resources/FinalModel_vessel_array.csv + FinalModel_parameters.csv, by",
              "# oxyline.io.circulatory_autogen.to_native_dict; inflow: Mynard & Smolich 2015 aortic",
              "# flow template from peterhcharlton/pwdb (MIT) scaled to FinalModel_obs_data.json.",
              "# Regenerate: benches/make_models_data.py. Licences and citations: NOTICE.",
              *[f"# importer note: {n}" for n in notes]]
    text = "\n".join(header) + "\n" + dump(d)
    if yaml.safe_load(text) != d:
        raise SystemExit("whole-body-140: YAML round trip changed the model")
    (OUT / "whole-body-140.yaml").write_text(text)
    print("whole-body-140", len(d["vessels"]), "vessels")
    shutil.copy(CA / "LICENSE", OUT / "LICENSE-circulatory_autogen")
    shutil.copy(PWDB / "LICENSE", OUT / "LICENSE-pwdb")


if __name__ == "__main__":
    main()
