"""Small rules for what a configuration declares: diode normals given to a few digits, the diodes' type.

* A normal ``[x, y, z]`` within :data:`NORMAL_EXACT_TOL` of unit length is taken as it is (normalised
  silently); within :data:`NORMAL_ROUNDED_TOL` it is a normal written to a few digits (a fitted normal to
  three digits is unit only to ~1e-3): normalised, with a note that the run prints and stores; beyond, it
  is refused (a wrong component, not rounding).
* ``[body] none = true``: a study of bare diodes: the body's size still places the diodes on its panels,
  but no body is rendered and none shadows them (the analytic model's body box is left out too).
* ``diode_type`` (top level of the TOML): the diodes' part, which decides the spectral band of
  ``--map band``: a name :mod:`simcore.radiometry.band` knows (e.g. "BPW34FS", "BPV23F"), or "unknown":
  then ``--map band`` is refused with a line naming the ways out (``band:DIODE`` to assume a part, or a
  broadband map). Left out: the BPW34FS, sunsim's default diode.
* Every table's keys are checked (:func:`check_keys`: an unknown key is refused with the closest allowed
  ones); lengths are given in mm (:data:`MM`), vectors as three finite numbers (:func:`vector3`).
"""
import difflib

import numpy as np

from simcore.errors import InvalidInputError

NORMAL_EXACT_TOL = 1e-5
# three digits round each component by <= 5e-4, moving the norm by <= 5e-4 (|x| + |y| + |z|) <= 8.7e-4
NORMAL_ROUNDED_TOL = 2e-3
UNKNOWN_DIODE = "unknown"
MM = 1e-3       # metres per millimetre: a configuration's lengths are given in mm


class ConfigError(InvalidInputError):
    """A satellite configuration that cannot be built; the message says what to change."""


def unit_normal(n, where):
    """Return (unit normal (3,), note or ''): ``n`` normalised under the rules of the module docstring."""
    n = np.asarray(n, dtype=float)
    norm = float(np.linalg.norm(n))
    if abs(norm - 1.0) > NORMAL_ROUNDED_TOL:
        raise ConfigError(f"{where}: normal {n.tolist()} is not a unit vector (norm {norm:.6f}, more than "
                                f"{NORMAL_ROUNDED_TOL:g} from 1); normalise it or give az_deg/el_deg")
    note = ""
    if abs(norm - 1.0) > NORMAL_EXACT_TOL:
        note = (f"{where}: normal {n.tolist()} has norm {norm:.6f} (written to a few digits); normalised to "
                f"{np.round(n / norm, 6).tolist()}")
    return n / norm, note


def diode_type(value, where):
    """Return the declared diode type (upper case, or 'unknown'), or None where none is declared."""
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{where}: diode_type must be a diode's part name (e.g. \"BPW34FS\") or "
                                f"\"{UNKNOWN_DIODE}\", got {value!r}")
    v = value.strip()
    return UNKNOWN_DIODE if v.lower() == UNKNOWN_DIODE else v.upper()


def body_none(value, where):
    """Return ``[body] none`` as a bool, or raise: it must be true or false."""
    if not isinstance(value, bool):
        raise ConfigError(f"{where}: [body] none must be true or false, got {value!r}")
    return value


def check_keys(table, allowed, where):
    """Refuse keys of ``table`` not in ``allowed``, naming the closest allowed ones (``where``: the table)."""
    unknown = [k for k in table if k not in allowed]
    if unknown:
        hints = []
        for k in unknown:
            close = difflib.get_close_matches(k, allowed, n=2, cutoff=0.5)
            hints.append(f"{k!r}" + (f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""))
        raise ConfigError(f"unknown key(s) in {where}: {', '.join(hints)}; allowed keys are {', '.join(allowed)}")


def vector3(value, what):
    """Return ``value`` as a float array (3,), or refuse it unless it is three finite numbers."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = np.full(0, np.nan)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ConfigError(f"{what} must be three finite numbers, got {value!r}")
    return v
