"""The OPS-SAT telemetry readers (simcore.environment.telemetry) on the shipped files and on corrupted copies.

Oracles: the shipped files' own published description (/work/shared/data/flight/opssat/README.md, copied to
simcore/data/flight/opssat/README.md) and counts taken with standard tools (`wc -l`, `grep -c`), stated at
each number."""

import numpy as np
import pytest

from simcore.environment import telemetry as T
from simcore.errors import InvalidInputError

LOG = T.OPSSAT_LOGS_2021 / "data_2021-04-16_17-17-36.csv"


def test_grains_export_as_published():
    h = T.read_opssat_attitude()
    # wc -l: 7251 lines = 18 header lines + the column line + 7232 rows; no rows of zeros in this file (README)
    assert len(h) == 7232 and h.dropped == {"zero_rows": 0}
    # the header describes the whole export (2020-11-15..30, 18044 samples), not the week present: kept, not checked
    assert h.header["samples"].startswith("18044") and h.header["window_end"].startswith("2020-11-30")
    assert h.epochs.iso()[0] == "2020-11-15T00:34:04.529Z" and h.epochs.iso()[-1] == "2020-11-21T14:16:14.531Z"
    # norms 0.956 .. 1.000 (README): normalised, the recorded ones kept
    assert 0.955 < h.norm_recorded.min() < 0.957 and np.allclose(np.linalg.norm(h.q_frame_from_body, axis=1), 1)
    assert h.frame == T.OPSSAT_FRAME and h.direction == "frame_to_body"
    # first row 0.16312,-0.12766,0.887638,-0.411332 scalar first, frame_to_body: the history holds its conjugate
    q0 = np.array([0.16312, -0.12766, 0.887638, -0.411332])
    assert np.allclose(h.q_frame_from_body[0], q0 * [1, -1, -1, -1] / np.linalg.norm(q0))


def test_grains_rows_of_zeros_are_left_out_and_counted(tmp_path):
    lines = T.OPSSAT_ATTITUDE.read_text().splitlines()
    lines[19 + 5] = lines[19 + 5].split(",")[0] + ",0,0,0,0"
    p = tmp_path / "z.csv"
    p.write_text("\n".join(lines[:19 + 20]) + "\n")
    h = T.read_opssat_attitude(p)
    assert len(h) == 19 and h.dropped == {"zero_rows": 1} and h.flags()["counts"]["dropped_zero_rows"] == 1


def _corrupt(tmp_path, src, edit):
    lines = src.read_text().splitlines()
    p = tmp_path / src.name
    out = edit(lines)
    if isinstance(out, bytes):
        p.write_bytes(out)
    else:
        p.write_text("\n".join(out) + "\n")
    return p


def _refused(reader, path, words):
    with pytest.raises(InvalidInputError) as exc:
        reader(path)
    msg = str(exc.value)
    assert words in msg and "\n" not in msg, msg


GRAINS_CASES = {
    "truncated in the header": (lambda L: L[:10], "truncated"),
    "truncated row": (lambda L: L[:30] + [L[30][:28]], "expected 5 values"),
    "binary": (lambda L: b"\x00\x01GRAINS\xff" * 50, "binary"),
    "wrong first line": (lambda L: ["# Exported from elsewhere"] + L[1:], "not a GRAINS export"),
    "wrong column line": (lambda L: L[:18] + ["# DATE TIME,CADC1003,CADC1002,CADC1004,CADC1005"] + L[19:], "wrong column line"),
    "non-numeric cell": (lambda L: L[:25] + [L[25].replace(",0.", ",zero.", 1)] + L[26:], "cannot read"),
    "non-monotonic times": (lambda L: L[:25] + [L[26], L[25]] + L[27:], "does not follow"),
    "bad time": (lambda L: L[:25] + ["2020-13-15 00:34:54.517" + L[25][23:]] + L[26:], "UTC time"),
    "norm far from 1": (lambda L: L[:25] + [L[25].split(",")[0] + ",0.5,0.1,0.1,0.1"] + L[26:], "norm 0.5"),
}


@pytest.mark.parametrize("case", sorted(GRAINS_CASES))
def test_grains_corrupted(tmp_path, case):
    edit, words = GRAINS_CASES[case]
    _refused(T.read_opssat_attitude, _corrupt(tmp_path, T.OPSSAT_ATTITUDE, edit), words)


def test_pd_file_as_published():
    pd = T.read_opssat_pd()
    # wc -l: 5048 lines = header + 5047 rows; README: 3 values slightly negative, 80 exactly pi/2 (printed 1.5708)
    assert pd.names == ("PD3", "PD6") and len(pd.epochs) == 5047
    c = pd.counts
    assert c["clipped_negative_PD3"] + c["clipped_negative_PD6"] == 3
    assert c["saturated_PD3"] + c["saturated_PD6"] == 80
    assert np.nanmin(pd.theta_rad) == 0.0 and (~pd.usable).sum() == 80
    assert pd.epochs.iso()[0] == "2020-11-15T00:34:04.000Z"
    # first row: PD3 0.594919 rad
    assert pd.reading[0, 0] == pytest.approx(np.sin(0.594919), abs=1e-12)


PD_CASES = {
    "truncated row": (lambda L: L[:40] + [L[40][:21]], "expected 6 values"),
    "binary": (lambda L: b"TIMESTAMP\x00\x00" * 40, "binary"),
    "wrong header": (lambda L: ["TIMESTAMP,PD6,PD3,A,B,C"] + L[1:], "header must start"),
    "non-numeric cell": (lambda L: L[:9] + [L[9].replace(",0.", ",nan?", 1)] + L[10:], "cannot read"),
    "non-monotonic times": (lambda L: L[:9] + [L[10], L[9]] + L[11:], "does not follow"),
    "negative beyond tolerance": (lambda L: L[:9] + [L[9].split(",")[0] + ",-0.2,0.1,1,1,1"] + L[10:], "below"),
    "above pi/2": (lambda L: L[:9] + [L[9].split(",")[0] + ",1.7,0.1,1,1,1"] + L[10:], "above pi/2"),
    "empty": (lambda L: [""], "empty"),
}


@pytest.mark.parametrize("case", sorted(PD_CASES))
def test_pd_corrupted(tmp_path, case):
    edit, words = PD_CASES[case]
    _refused(T.read_opssat_pd, _corrupt(tmp_path, T.OPSSAT_PD, edit), words)


def test_log_2021_as_published():
    hist, r = T.read_opssat_log_2021(LOG)
    # wc -l 851 = header + 850 rows; the first row has x for PD1/PD2 and the quaternion (not acquired)
    assert len(r.epochs) == 850 and r.names == tuple(f"PD{k}" for k in range(1, 7))
    assert r.epochs.iso()[1] == "2021-04-16T17:17:44.649Z"          # 1618593464649 ms (Unix)
    assert np.isnan(r.theta_rad[0, 0]) and np.isnan(r.theta_rad[0, 1])
    # the shifted header: row 2's PD3 (CADC0888) 0.6714748 with flag true, PD1 (CADC0884) 0.00548852 flag false
    assert r.theta_rad[1, 2] == 0.6714748 and r.flag_valid[1, 2]
    assert r.theta_rad[1, 0] == 0.00548852 and not r.flag_valid[1, 0]
    # quaternion CADC1002..1005 of row 2: -0.50691664, 0.75584435, 0.29629943, -0.28639293 (frame_to_body)
    q = np.array([-0.50691664, 0.75584435, 0.29629943, -0.28639293])
    assert np.allclose(hist.q_frame_from_body[0], q * [1, -1, -1, -1] / np.linalg.norm(q))
    c = hist.flags()["counts"]
    assert c["dropped_not_acquired"] == 1 and c["samples"] + c["dropped_repeated"] + 1 == 850


def test_every_shipped_2021_log_reads():
    for p in sorted(T.OPSSAT_LOGS_2021.glob("*.csv")):
        hist, r = T.read_opssat_log_2021(p)
        assert len(hist) > 10 and len(r.epochs) >= 398


LOG_CASES = {
    "truncated row": (lambda L: L[:40] + [L[40][:50]], "expected 20 values"),
    "binary": (lambda L: b"CADC0884\x00\xff" * 40, "binary"),
    "wrong header": (lambda L: ["TIME," + L[0]] + L[1:], "not an OPS-SAT 2021 log header"),
    "non-numeric cell": (lambda L: L[:9] + [L[9].replace(",0.", ",o.", 1)] + L[10:], "cannot read"),
    "non-monotonic times": (lambda L: L[:9] + [L[10], L[9]] + L[11:], "does not follow"),
    "bad flag": (lambda L: L[:9] + [L[9].replace(",true,", ",maybe,", 1)] + L[10:], "validity flag"),
    "norm far from 1": (lambda L: L[:9] + [",".join(L[9].split(",")[:16] + ["0.3", "0.3", "0.3", "0.3"])] + L[10:],
                        "norm 0.6"),
}


@pytest.mark.parametrize("case", sorted(LOG_CASES))
def test_log_2021_corrupted(tmp_path, case):
    edit, words = LOG_CASES[case]
    _refused(T.read_opssat_log_2021, _corrupt(tmp_path, LOG, edit), words)


def test_read_attitude_history_tells_formats(tmp_path):
    assert len(T.read_attitude_history(T.OPSSAT_ATTITUDE)) == 7232
    assert T.read_attitude_history(LOG).direction == "frame_to_body"
    rel = tmp_path / "rel.csv"
    rel.write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n10,1,0,0,0\n")
    with pytest.raises(InvalidInputError, match="relative times"):
        T.read_attitude_history(rel)
    h = T.read_attitude_history(rel, start="2020-01-01T00:00:00Z")
    assert h.epochs.iso() == ["2020-01-01T00:00:00.000Z", "2020-01-01T00:00:10.000Z"] and h.frame == "GCRF"
    other = tmp_path / "x.csv"
    other.write_text("a,b\n1,2\n")
    with pytest.raises(InvalidInputError, match="not an attitude file"):
        T.read_attitude_history(other)


def test_shipped_data_has_its_licence_and_readme():
    for name in ("LICENSE_source.md", "README.md", "tle_2020-11-06.txt", "tle_2021-02-08.txt"):
        assert (T.OPSSAT_DIR / name).is_file(), name
    assert "MIT" in (T.OPSSAT_DIR / "README.md").read_text() or "Permission is hereby granted" in \
        (T.OPSSAT_DIR / "LICENSE_source.md").read_text()
