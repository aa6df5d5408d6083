"""One cycle of the built-in whole trees (``adan56-st``, ``whole-body-140-st``) through the
command line, flow only and with oxygen, each in a fresh ``oxyline run`` process measured by
``/usr/bin/time -v`` (wall, CPU = user + system, peak RSS). The model runs with its own
settings (their files' ``simulation``: one cycle of generalized-alpha at dt = 1 ms, vessel
output of the named arteries every 10 ms) and, for oxygen, an ``oxygen`` section with the
default Lévêque closure (inlet 95 mmHg, wall 60 mmHg). The scale budget: 1e6 segments with
O2 in < 180 s and < 3 GB. Prints a markdown table for benches/results.md.

Run: python benches/bench_whole_trees.py [--models adan56-st whole-body-140-st]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

OXYGEN = {"inlet": {"po2": 95.0}, "wall": {"model": "leveque", "po2": 60.0}}


def timed(argv: list[str]) -> dict[str, float]:
    """Run ``argv`` under /usr/bin/time -v: wall s, CPU s, peak RSS MB."""
    p = subprocess.run(["/usr/bin/time", "-v", *argv], capture_output=True, text=True,
                       check=False)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed:\n{p.stderr[-2000:]}")

    def field(name: str) -> str:
        match = re.search(rf"{re.escape(name)}: (.+)", p.stderr)
        assert match, name
        return match.group(1).strip()

    wall = 0.0
    for part in field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":"):
        wall = 60.0 * wall + float(part)
    return {"wall": wall, "cpu": float(field("User time (seconds)"))
            + float(field("System time (seconds)")),
            "peak_mb": float(field("Maximum resident set size (kbytes)")) / 1024.0}


def main() -> None:
    import oxyline

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=list(oxyline.catalogue.WHOLE_TREES))
    args = ap.parse_args()
    exe = [sys.executable, "-m", "oxyline.cli"]  # the command line of this interpreter
    rows: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.models:
            data: dict[str, Any] = oxyline.catalogue.load_dict(name)
            flow = Path(tmp) / f"{name}.json"
            flow.write_text(json.dumps(data))
            o2 = Path(tmp) / f"{name}-o2.json"
            o2.write_text(json.dumps({**data, "oxygen": OXYGEN}))
            c0 = time.process_time()  # load alone (growth + assembly), in this process
            segments = oxyline.catalogue.load(name).network.summary()["segments"]
            load_cpu = time.process_time() - c0
            res = {}
            for label, path in (("flow", flow), ("o2", o2)):
                res[label] = timed([*exe, "run", str(path), "--quiet",
                                    "-o", str(Path(tmp) / f"{path.stem}.nc")])
                print(name, label, res[label], flush=True)
            f, o = res["flow"], res["o2"]
            rows.append(f"| {name} | {segments:,} | {load_cpu:.1f} | {f['wall']:.1f} | "
                        f"{f['cpu']:.1f} | {f['peak_mb']:.0f} | {o['wall']:.1f} | {o['cpu']:.1f} | "
                        f"{o['peak_mb']:.0f} | {o['cpu'] / f['cpu']:.2f} |")
    print(f"\nload average {os.getloadavg()[0]:.1f} (1 min) at the end\n")
    print("| model | segments | load CPU s | flow wall s | flow CPU s | flow peak MB | O2 wall s "
          "| O2 CPU s | O2 peak MB | O2/flow CPU |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
