"""Memory estimate vs measured peak: for each case, a child process warms up
(imports, a tiny run), then loads the model and runs it; the table compares the estimate the
`max_memory` check uses (model + output, `oxyline.memory`) with the peak resident memory the
load and run added (VmHWM − VmRSS before). Linux only (/proc).

    python benches/bench_memory.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

CHILD = textwrap.dedent("""
    import json, sys, oxyline
    from oxyline import memory
    from oxyline.run import _output_size, _settings

    def rss(key):
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key):
                    return float(line.split()[1]) * 1024

    oxyline.simulate("bifurcation", cycles=1)
    base = rss("VmRSS:")
    name, max_length, hb, kw = json.loads(sys.argv[1])
    d = oxyline.load_model(name).to_dict()
    if max_length:
        d["segmentation"] = {"max_length": max_length}
        for v in d["vessels"]:
            v.pop("segments", None)
    if hb:
        d["oxygen"]["hemoglobin"] = hb
    m = oxyline.load_model(d)
    s = _settings(m, kw)
    model = memory.run_estimate(m.network, s)
    output = _output_size(m, s)[0]
    oxyline.simulate(m, **kw)
    print(json.dumps([m.summary()["segments"], model, output, rss("VmHWM:") - base]))
""")

CASES = [
    ("adan56", 1e-3, None, {"cycles": 1, "segments": False}),
    ("adan56", 3e-4, None, {"cycles": 1, "segments": False}),
    ("adan56", 1e-4, None, {"cycles": 1, "segments": False, "method": "generalized-alpha"}),
    ("adan56", 3e-4, None, {"cycles": 1}),
    ("paper-bifurcated", 2e-5, None, {"cycles": 1, "segments": False}),
    ("paper-bifurcated", 2e-5, "hill", {"cycles": 1, "segments": False,
                                        "method": "generalized-alpha"}),
    ("whole-body-140", None, None, {"cycles": 10, "until_periodic": None,
                                    "output_cycles": "all"}),
]


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'model':18}{'max_length':>11}{'hb':>6}{'segments':>10}{'est model MB':>14}"
          f"{'est output MB':>15}{'peak MB':>10}{'est/peak':>10}")
    for case in CASES:
        done = subprocess.run([sys.executable, "-c", CHILD, json.dumps(case)],
                              check=False, capture_output=True, text=True,
                              env={**os.environ, "OXYLINE_MAX_MEMORY": "none"})
        if done.returncode:
            print(case, done.stderr[-500:])
            continue
        seg, model, output, peak = json.loads(done.stdout.splitlines()[-1])
        print(f"{case[0]:18}{case[1] or '-':>11}{case[2] or '-':>6}{seg:>10}{model / 1e6:>14.1f}"
              f"{output / 1e6:>15.1f}{peak / 1e6:>10.1f}{(model + output) / peak:>10.2f}",
              flush=True)


if __name__ == "__main__":
    main()
