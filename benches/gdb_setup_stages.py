"""The resident set and each stage's own peak while a large run sets up, stage by stage, read
from the running process at the entry of each stage of ``run::pass`` (a gdb script: the built
extension's symbols, no change to the product):

    SO=python/oxyline/_core.abi3.so SEGMENTS=1048572 gdb -batch -x benches/gdb_setup_stages.py \\
        --args python benches/profile_memory.py --depth 18 --config o2-k

At each breakpoint it prints VmRSS and the high-water mark since the previous one (VmHWM,
reset through ``/proc/PID/clear_refs``), in bytes per segment (``SEGMENTS``). With
``STOP_AT_SPECIES=1`` the process is killed when the species' state starts (the setup only).
The high-water mark ``profile_memory.py`` prints is then per stage, not the run's. (After the
kill, gdb's own Python may print a traceback as it exits: harmless.)
"""

import os
import re
import subprocess

import gdb  # only inside gdb

STAGES = [
    "oxyline_core::run::two_pass::run_two_pass",
    "oxyline_core::run::pass::run",
    "oxyline_core::run::plan::Plan::new",
    "oxyline_core::run::plan::steady_start",
    "oxyline_core::run::plan::Plan::initial_state",
    "oxyline_core::integrate::rk4::Rk4::new",
    "oxyline_core::integrate::rk4::Rk4::make_consistent",
    "oxyline_core::integrate::rk4::Rk4::derivative",
    "oxyline_core::integrate::steady::SteadyCache::release",
    "oxyline_core::integrate::genalpha::GenAlpha::new",
    "oxyline_core::integrate::genalpha::GenAlpha::factor_ahead",
    "oxyline_core::run::coupling::Species::start",
    "oxyline_core::run::recorder::Recorder::new",
    "oxyline_core::run::cycle::Cycles::new",
    "oxyline_core::run::cycle::Cycles::run",
    "oxyline_core::run::cycle::Cycles::output_row",
    "oxyline_core::run::outcome::Outcome::of",
]
SEGMENTS = float(os.environ.get("SEGMENTS", "1"))
hits: dict[str, int] = {}
last = ["start"]


class Stage(gdb.Breakpoint):
    """Prints the stage that ends here: its peak, and the resident set at this entry."""

    def stop(self) -> bool:
        hits[self.location] = hits.get(self.location, 0) + 1
        if "output_row" in self.location and hits[self.location] > 3:
            return False
        pid = gdb.selected_inferior().pid
        status = {}
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                k, _, v = line.partition(":")
                if k in ("VmRSS", "VmHWM"):
                    status[k] = float(v.split()[0]) * 1024
        with open(f"/proc/{pid}/clear_refs", "w") as f:
            f.write("5")  # reset the high-water mark
        parts = self.location.strip("'").split("::")
        name = "::".join(parts[-3:-1]) if len(parts) > 1 else parts[0]
        print(f"STAGE {last[0]:<40s} peak {status['VmHWM'] / SEGMENTS:7.0f} B/seg | at entry "
              f"of {name}: rss {status['VmRSS'] / SEGMENTS:7.0f} B/seg", flush=True)
        last[0] = name
        if "Species::start" in self.location and os.environ.get("STOP_AT_SPECIES"):
            gdb.post_event(lambda: gdb.execute("kill"))
        return False


gdb.execute("set breakpoint pending on")
gdb.execute("set pagination off")
gdb.execute("set print thread-events off")
names = subprocess.run(f"nm {os.environ['SO']} | awk '{{print $3}}' | c++filt", shell=True,
                       capture_output=True, text=True, check=True).stdout.split()
for stage in STAGES:
    for n in names:
        if re.fullmatch(re.escape(stage) + r"::h[0-9a-f]{16}", n):
            Stage(f"'{n}'")
Stage("malloc_trim")  # the pass's trims of freed pages
gdb.execute("run")
