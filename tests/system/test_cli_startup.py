"""The command line starts without the heavy libraries (issue 32 item 1): building every subcommand's parser,
``sunsim --help`` and an argument error import none of xarray, scipy, matplotlib, trimesh, pandas, Dr.Jit or
Mitsuba; the subcommands import them when they run. (The timing itself is benchmarks/bench_startup.py's.)"""
import json
import subprocess
import sys

import pytest

HEAVY = ("xarray", "scipy", "matplotlib", "trimesh", "pandas", "drjit", "mitsuba", "dask", "h5netcdf", "sgp4")

PROBE = """
import json, sys
from simcore.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
{extra}
print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({heavy!r}))))
"""


def _heavy_imported(argv, extra=""):
    """Return the heavy top-level packages a fresh interpreter holds after ``sunsim ARGV`` (and ``extra``)."""
    out = subprocess.run([sys.executable, "-c", PROBE.format(argv=argv, extra=extra, heavy=HEAVY)],
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["attitude-study", "--help"],
                                  ["run", "--no-such-option"], ["estimate", "--filter", "no-such-filter", "x.nc"]])
def test_parser_imports_nothing_heavy(argv):
    assert _heavy_imported(argv) == []


def test_the_probe_sees_a_heavy_import():
    # the wrong input: a study module imported at parser time (as cli.py did for the attitude study's choices)
    assert "xarray" in _heavy_imported(["--help"], extra="import simcore.studies.attitude")
