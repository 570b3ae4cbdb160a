"""Benchmark the command line's start-up: ``sunsim --help`` and argument errors against ``python -c "import xarray"``.

Each command runs as the user runs it, a fresh process (``python -m simcore.cli``, what the ``sunsim`` entry point
calls), and the three are interleaved ``--repeat`` times, so that another process on a shared machine slows all of
them alike; the medians and their ratios to the xarray import are printed.

    .venv/bin/python benchmarks/bench_startup.py [--repeat N]

Acceptance (issue 32): ``sunsim --help`` at most 1.5 x the xarray import. Last line: one JSON object.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

COMMANDS = {
    "import xarray": [sys.executable, "-c", "import xarray"],
    "sunsim --help": [sys.executable, "-m", "simcore.cli", "--help"],
    "sunsim run --no-such-option": [sys.executable, "-m", "simcore.cli", "run", "--no-such-option"],
}
EXPECTED_EXIT = {"import xarray": 0, "sunsim --help": 0, "sunsim run --no-such-option": 2}
LIMIT = 1.5   # sunsim --help / import xarray, issue 32


def timed(cmd):
    """Return the wall seconds and exit status of ``cmd`` run to its end in a fresh process."""
    t0 = time.perf_counter()
    rc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode
    return time.perf_counter() - t0, rc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="interleaved rounds (default %(default)s)")
    a = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    times = {k: [] for k in COMMANDS}
    for _ in range(a.repeat):
        for name, cmd in COMMANDS.items():
            dt, rc = timed(cmd)
            if rc != EXPECTED_EXIT[name]:
                raise SystemExit(f"{name} exited {rc}, expected {EXPECTED_EXIT[name]}")
            times[name].append(dt)
    med = {k: statistics.median(v) for k, v in times.items()}
    base = med["import xarray"]
    for name, m in med.items():
        print(f"{name:<30} median {m:6.3f} s  ({m / base:4.2f} x import xarray; "
              f"min {min(times[name]):.3f} s, max {max(times[name]):.3f} s)")
    ratio = med["sunsim --help"] / base
    print(f"sunsim --help / import xarray: {ratio:.2f} (limit {LIMIT}); {a.repeat} interleaved rounds, "
          f"load average (1 min) at the start {load0:.2f} on {os.cpu_count()} cores")
    print(json.dumps({"bench": "startup", "median_s": {k: round(v, 4) for k, v in med.items()},
                      "help_ratio": round(ratio, 3),
                      "parse_error_ratio": round(med["sunsim run --no-such-option"] / base, 3),
                      "limit": LIMIT, "meets_limit": bool(ratio <= LIMIT), "repeat": a.repeat,
                      "load_at_start": round(load0, 2)}))


if __name__ == "__main__":
    main()
