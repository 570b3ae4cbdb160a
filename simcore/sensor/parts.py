"""Named sensor parts from a data table: one look-up, with close matches for a mistyped name."""
import difflib
from dataclasses import dataclass
import tomllib
from importlib import resources

from simcore.errors import InvalidInputError


@dataclass(frozen=True)
class PartSpec:
    """A sensor part of a shipped table: its name and where its numbers come from."""

    name: str
    source: str


def find_part(name, parts, kind):
    """Return the entry of ``parts`` ({name: spec}) called ``name``, ignoring case; raise an
    InvalidInputError naming close matches otherwise. ``kind`` ('gyro', 'magnetometer') words the message."""
    by_upper = {k.upper(): v for k, v in parts.items()}
    if str(name).upper() in by_upper:
        return by_upper[str(name).upper()]
    close = difflib.get_close_matches(str(name).upper(), list(by_upper), n=3, cutoff=0.4)
    hint = f"; did you mean {', '.join(by_upper[c].name for c in close)}?" if close else ""
    raise InvalidInputError(f"unknown {kind} {name!r}{hint} (known: {', '.join(parts)})")


def load_parts(filename, spec_class, units):
    """Return {name: spec_class} of the shipped table ``simcore/data/<filename>`` (TOML, one table per part).

    ``units`` maps a key as written in the table (in data-sheet units) to (field of ``spec_class``,
    factor to SI); other keys are taken as they are.
    """
    text = resources.files("simcore").joinpath("data", filename).read_text()
    out = {}
    for name, entry in tomllib.loads(text).items():
        kw = {"name": name}
        for k, v in entry.items():
            field, scale = units.get(k, (k, None))
            kw[field] = v if scale is None else float(v) * scale
        out[name] = spec_class(**kw)
    return out
